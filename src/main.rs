//! ahcmon command line: parses arguments and dispatches to the command (`app/`); the work is
//! in the library.

mod app;
mod cli;

use clap::Parser;
use cli::{Cli, Command};
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = Cli::parse();
    app::log::init(cli.verbose, cli.quiet);
    // replay and eval run on this pool (two filters of a vehicle on two cores): give its
    // workers the main thread's stack size, the filter structs are moved by value.
    let _ = rayon::ThreadPoolBuilder::new()
        .stack_size(8 << 20)
        .build_global();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // The chain, each link once: an error that already says its source (`{path}:
            // {source}`) is not followed by the source again.
            let mut msg = String::new();
            for link in e.chain().map(|c| c.to_string()) {
                if msg.ends_with(&link) {
                    continue;
                }
                if !msg.is_empty() {
                    msg.push_str(": ");
                }
                msg.push_str(&link);
            }
            eprintln!(
                "ahcmon: error: {}",
                ahcmon::output::printable(&msg.replace('\n', " "))
            );
            ExitCode::from(if app::is_input_error(&e) { 2 } else { 1 })
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    app::claim_stdout(&cli.command.stdout_flags())?;
    match cli.command {
        Command::Eval(a) => app::eval::run(a),
        Command::Thresholds(a) => app::thresholds::run(a),
        Command::Sim(a) => app::sim::run(a),
        Command::Monitor(a) => app::monitor::run(a),
        Command::Demo(a) => app::monitor::demo(a),
        Command::Calibrate(a) => app::calibrate::run(a),
        Command::Replay(a) => app::replay::run(a),
        Command::Scan(a) => app::scan::run(a),
        Command::History(a) => app::history::run(a),
        Command::Benchmark(a) => app::benchmark::run(a),
        Command::Completions(a) => app::shell::completions(a),
        Command::Man(a) => app::shell::man(a),
    }
}
