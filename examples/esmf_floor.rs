//! How close a set filter's centre can come to the truth in a paper scenario, whatever its
//! process-noise set: the question behind issue 3's finding (d), "MIT-ESMF converges faster
//! than ESMF in Fig. 9".
//!
//! The MIT-ESMF is the ESMF with its process-noise diagonal `q` adapted. So if no `q` brings the
//! ESMF's gamma centre within the settling tolerance (0.05) and keeps it there, no MIT-ESMF can
//! settle either, and the finding can only show as a smaller error, not as a settling time.
//! This runs the ESMF (the paper's trace-optimal beta and rho, as shipped) with `q` scaled:
//! the rate entries by 1/4 to 16 and the AHC entries by 1 to 1/1000 (a fixed `q` near zero is
//! what an adaptation that only ever lowers the AHC entries tends to), and prints the mean
//! |gamma centre - truth| over the seeds in windows after the fault onset, next to the
//! MIT-ESMF as shipped (paired: on how many seeds its window error is below the ESMF's).
//!
//! Why the floor is where it is: every prediction widens the whole set by 1/(1 - beta), and
//! one step's data tell of gamma what a rate increment against the process-noise set can,
//! so the set holds about one step's worth of gamma information, averaged over the last
//! 1/beta steps; in trim gamma and delta are nearly collinear (u_lon barely moves), so the
//! gamma extent stays near ±2 and the centre wanders with the process noise.
//!
//! `cargo run --release --example esmf_floor -- [SCENARIO] [--seeds N]`
//! (default `paper-fig9-uniform-step`, 30 seeds).

use ahcmon::estimate::{AdaptationParams, Esmf, EsmfParams, MitEsmf};
use ahcmon::eval::bank::{BankNoise, set_p0, x0};
use ahcmon::scenario::{NamedScenario, resolve};
use ahcmon::sim::paper::{ESTIMATED, PaperSim, PaperSimConfig};
use anyhow::{Context, bail};
use nalgebra::Vector3;

/// Windows after the onset (s).
const WINDOWS: [(f64, f64); 4] = [(0.0, 1.0), (1.0, 3.0), (3.0, 10.0), (10.0, 30.0)];

/// Mean |gamma error| per window of one run.
type WindowErrors = [f64; WINDOWS.len()];

/// One filter step from (u, y) to its gamma centre.
type GammaStep = Box<dyn FnMut(&[f64], &Vector3<f64>) -> anyhow::Result<f64>>;

fn main() {
    if let Err(e) = study() {
        eprintln!("esmf_floor: {e:#}");
        std::process::exit(2);
    }
}

fn study() -> anyhow::Result<()> {
    let mut name = "paper-fig9-uniform-step".to_string();
    let mut seeds = 30u64;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seeds" => {
                seeds = args
                    .next()
                    .context("--seeds needs a number")?
                    .parse()
                    .context("--seeds needs a number")?
            }
            s if s.starts_with('-') => bail!("unknown option {s}"),
            s => name = s.to_string(),
        }
    }
    let named = resolve(&name)?;
    if !named.scenario.is_paper() {
        bail!("{name} is a vehicle scenario; this study runs the paper helicopter's");
    }
    let Some(onset) = named.scenario.faults.first().map(|f| f.t) else {
        bail!("{name} has no fault");
    };
    let mit: Vec<WindowErrors> = (0..seeds)
        .map(|i| run(&named, named.scenario.seed + i, onset, None))
        .collect::<anyhow::Result<_>>()?;
    println!(
        "{name}, {seeds} seeds: mean |gamma centre - truth| after the onset at {onset} s \
         (windows in s after it)"
    );
    print!("{:<28}", "filter, q scaling");
    for (lo, hi) in WINDOWS {
        print!("{:>16}", format!("{lo}-{hi}"));
    }
    println!();
    print_row("mit-esmf as shipped", &mit, None);
    for rate_scale in [0.25, 1.0, 4.0, 16.0] {
        for ahc_scale in [1.0, 0.01, 0.001] {
            let esmf: Vec<WindowErrors> = (0..seeds)
                .map(|i| {
                    let seed = named.scenario.seed + i;
                    run(&named, seed, onset, Some((rate_scale, ahc_scale)))
                })
                .collect::<anyhow::Result<_>>()?;
            let label = format!("esmf, rates x{rate_scale} ahc x{ahc_scale}");
            print_row(&label, &esmf, Some(&mit));
        }
    }
    println!("(n/N: seeds on which the MIT-ESMF's window error is below this row's)");
    Ok(())
}

fn print_row(label: &str, runs: &[WindowErrors], mit: Option<&[WindowErrors]>) {
    print!("{label:<28}");
    for w in 0..WINDOWS.len() {
        let mean = runs.iter().map(|r| r[w]).sum::<f64>() / runs.len() as f64;
        match mit {
            Some(mit) => {
                let below = mit.iter().zip(runs).filter(|(m, e)| m[w] < e[w]).count();
                print!("{:>16}", format!("{mean:.4} {below}/{}", runs.len()));
            }
            None => print!("{mean:>16.4}"),
        }
    }
    println!();
}

/// One run: the MIT-ESMF as shipped (`scales` None) or the ESMF with `q` scaled.
fn run(
    named: &NamedScenario,
    seed: u64,
    onset: f64,
    scales: Option<(f64, f64)>,
) -> anyhow::Result<WindowErrors> {
    let scn = &named.scenario;
    let mut sim = PaperSim::new(PaperSimConfig {
        dt: scn.dt(),
        forward_speed: scn.forward_speed_mps,
        process_noise: scn.process_noise.clone(),
        measurement_noise: scn.measurement_noise.clone(),
        faults: scn.faults.clone(),
        dither: scn.dither.clone(),
        seed,
    })
    .map_err(anyhow::Error::msg)?;
    let noise = BankNoise::nominal(&scn.process_noise, &scn.measurement_noise);
    let (model, params) = (sim.model.clone(), EsmfParams::default());
    let mut q = noise.set_q();
    let mut filter: GammaStep = match scales {
        None => {
            let adapt = AdaptationParams::default();
            let mut mit = MitEsmf::new(model, params, adapt, x0(), set_p0(), q, noise.set_r());
            Box::new(move |u, y| {
                mit.try_step(u, y)?;
                Ok(mit.esmf.x[3])
            })
        }
        Some((rate_scale, ahc_scale)) => {
            for (i, v) in q.iter_mut().enumerate() {
                *v *= if i < 3 { rate_scale } else { ahc_scale };
            }
            let mut esmf = Esmf::new(model, params, x0(), set_p0(), q, noise.set_r());
            Box::new(move |u, y| {
                esmf.try_step(u, y)?;
                Ok(esmf.x[3])
            })
        }
    };
    let mut sums = [0.0; WINDOWS.len()];
    let mut counts = [0usize; WINDOWS.len()];
    for _ in 0..scn.steps() {
        let s = sim.step();
        let gamma = filter(&s.u, &s.y)?;
        let after = s.t - onset;
        if let Some(w) = WINDOWS
            .iter()
            .position(|(lo, hi)| after >= *lo && after < *hi)
        {
            sums[w] += (gamma - s.truth[ESTIMATED].0).abs();
            counts[w] += 1;
        }
    }
    Ok(std::array::from_fn(|w| sums[w] / counts[w].max(1) as f64))
}
