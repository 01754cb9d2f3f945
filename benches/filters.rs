//! One step of each filter on the paper model (n = 5), and the whole 2000-step paper run of all
//! five filters with the simulator (the paper's Table 2 took 31 s for the five).

// A developer tool: a failed unwrap ends it with the reason.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ahcmon::estimate::{
    AdaptationParams, Esmf, EsmfParams, KfUkf, MitEsmf, MitUkf, SlaveKfParams, Ukf, UkfParams,
};
use ahcmon::eval::bank::{BankNoise, kalman_p0, set_p0, x0};
use ahcmon::eval::run_scenario;
use ahcmon::model::PaperHeli;
use ahcmon::scenario;
use ahcmon::sim::paper::{PaperSample, PaperSim, paper_params};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn data() -> (Vec<PaperSample>, BankNoise) {
    let named = scenario::resolve("paper-fig5-gaussian").unwrap();
    let s = &named.scenario;
    let mut sim = PaperSim::new(s.paper_sim_config(1)).unwrap();
    (
        (0..s.steps()).map(|_| sim.step()).collect(),
        BankNoise::nominal(&s.process_noise, &s.measurement_noise),
    )
}

/// Time one step, cycling through a recorded run (the filter keeps going; it never sees the end).
macro_rules! bench_step {
    ($c:expr, $name:expr, $filter:expr, $data:expr) => {{
        let mut f = $filter;
        let mut k = 0usize;
        $c.bench_function($name, |b| {
            b.iter(|| {
                let s = &$data[k % $data.len()];
                k += 1;
                let _ = black_box(f.try_step(black_box(&s.u), black_box(&s.y)));
            })
        });
    }};
}

fn steps(c: &mut Criterion) {
    let (data, n) = data();
    let m = PaperHeli::new(paper_params(10.0), 0.02);
    let (u, a) = (UkfParams::default(), AdaptationParams::default());
    bench_step!(
        c,
        "step/ukf",
        Ukf::<_, 5, 3, 11>::new(m.clone(), u, x0(), kalman_p0(), n.kalman_q(), n.kalman_r()),
        data
    );
    bench_step!(
        c,
        "step/kf-ukf",
        KfUkf::<_, 5, 3, 11>::new(
            m.clone(),
            u,
            a,
            SlaveKfParams::default(),
            x0(),
            kalman_p0(),
            n.kalman_q(),
            n.kalman_r()
        ),
        data
    );
    bench_step!(
        c,
        "step/mit-ukf",
        MitUkf::<_, 5, 3, 11>::new(
            m.clone(),
            u,
            a,
            x0(),
            kalman_p0(),
            n.kalman_q(),
            n.kalman_r()
        ),
        data
    );
    bench_step!(
        c,
        "step/esmf",
        Esmf::new(
            m.clone(),
            EsmfParams::default(),
            x0(),
            set_p0(),
            n.set_q(),
            n.set_r()
        ),
        data
    );
    bench_step!(
        c,
        "step/mit-esmf",
        MitEsmf::new(
            m.clone(),
            EsmfParams::default(),
            a,
            x0(),
            set_p0(),
            n.set_q(),
            n.set_r()
        ),
        data
    );
}

fn paper_run(c: &mut Criterion) {
    let named = scenario::resolve("paper-fig8-noise-step").unwrap();
    let mut g = c.benchmark_group("paper-run");
    g.sample_size(20);
    g.bench_function("2000 steps, sim + five filters + scoring", |b| {
        b.iter(|| black_box(run_scenario(&named, 1, false).unwrap()))
    });
    g.finish();
}

/// Quad X with a_z: n = 11, m = 4 (target: ≤ 10 µs per step per filter; the set filter's is
/// four actuators' polygons cut by their output bounds and those bounds' changes over six lags).
fn vehicle_steps(c: &mut Criterion) {
    use ahcmon::estimate::vehicle::{FilterPair, FilterSetup};
    use ahcmon::sim::vehicle::{VehicleSim, VehicleSimConfig};
    use ahcmon::telemetry::Profile;
    let profile = Profile::resolve("quad-x").unwrap();
    let mut sim = VehicleSim::new(VehicleSimConfig::calm(profile.clone(), 0.02, 1)).unwrap();
    let data: Vec<_> = (0..2000).map(|_| sim.step()).collect();
    let setup = FilterSetup::<11, 4>::from_profile(&profile, 0.02).unwrap();
    let mut g = c.benchmark_group("vehicle-step-n11");
    for which in ["mit-ukf", "mit-esmf", "set"] {
        g.bench_function(which, |b| {
            let mut pair = FilterPair::<11, 4, 23>::new(setup.clone());
            let mut i = 0;
            b.iter(|| {
                let s = &data[i % data.len()];
                i += 1;
                let y = nalgebra::SVector::<f64, 4>::from_column_slice(&s.y);
                match which {
                    "mit-ukf" => black_box(pair.ukf.try_step(&s.u[..4], &y).is_ok()),
                    "mit-esmf" => black_box(pair.esmf.try_step(&s.u[..4], &y).is_ok()),
                    _ => black_box(pair.set.try_step(&s.u[..4], &y).is_ok()),
                }
            })
        });
    }
    g.finish();
}

criterion_group!(benches, steps, paper_run, vehicle_steps);
criterion_main!(benches);
