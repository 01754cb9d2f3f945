//! `completions` and `man`: generated from the command line's own definition (clap), so they
//! name every command and flag there is.

use crate::cli::{Cli, CompletionsArgs, ManArgs};
use anyhow::Context;
use clap::CommandFactory;

pub fn completions(a: CompletionsArgs) -> anyhow::Result<()> {
    let mut script = Vec::new();
    clap_complete::generate(a.shell, &mut Cli::command(), "ahcmon", &mut script);
    out!(
        "{}",
        String::from_utf8(script).context("a completion script that is not UTF-8")?
    );
    Ok(())
}

pub fn man(a: ManArgs) -> anyhow::Result<()> {
    let cmd = Cli::command();
    match a.dir {
        Some(dir) => {
            std::fs::create_dir_all(&dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            clap_mangen::generate_to(cmd, &dir)
                .with_context(|| format!("cannot write the pages into {}", dir.display()))?;
            tracing::info!("manual pages written into {}", dir.display());
        }
        None => {
            let mut page = Vec::new();
            clap_mangen::Man::new(cmd)
                .render(&mut page)
                .context("cannot render the manual page")?;
            out!(
                "{}",
                String::from_utf8(page).context("a manual page that is not UTF-8")?
            );
        }
    }
    Ok(())
}
