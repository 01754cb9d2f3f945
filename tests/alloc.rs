//! The estimator step is the hot path: a counting global allocator shows that 1000 steps of each
//! filter allocate nothing on the heap.

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ahcmon::estimate::vehicle::{Identified, IdentifiedKind};
use ahcmon::estimate::{
    AdaptationParams, Esmf, EsmfParams, KfUkf, MitEsmf, MitUkf, SlaveKfParams, Ukf, UkfParams,
};
use ahcmon::eval::bank::{BankNoise, kalman_p0, set_p0, x0};
use ahcmon::model::PaperHeli;
use ahcmon::sim::noise::{NoiseKind, NoiseSchedule};
use ahcmon::sim::paper::{PaperSample, PaperSim, PaperSimConfig, paper_params};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};

struct Counting;
static ALLOCS: AtomicU64 = AtomicU64::new(0);

thread_local! {
    /// Set on the thread being measured: the test harness's own threads (printing another
    /// test's result meanwhile) allocate too, and must not count.
    static MEASURING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

fn measuring() -> bool {
    MEASURING.try_with(|m| m.get()).unwrap_or(false)
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if measuring() {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if measuring() {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;
/// The counter is process-wide: tests that count take this so they do not count each other.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Heap allocations made by `f` on this thread.
fn count<F: FnMut()>(mut f: F) -> u64 {
    let before = ALLOCS.load(Ordering::SeqCst);
    MEASURING.with(|m| m.set(true));
    f();
    MEASURING.with(|m| m.set(false));
    ALLOCS.load(Ordering::SeqCst) - before
}

#[test]
fn a_thousand_steps_of_each_filter_allocate_nothing() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let process = NoiseSchedule::constant(NoiseKind::Gaussian, 1e-4);
    let measurement = NoiseSchedule::constant(NoiseKind::Gaussian, 2.89e-6);
    let fault: ahcmon::sim::fault::Fault =
        toml::from_str("actuator='lon'\nt=8.0\ngamma=0.5").unwrap();
    let mut sim = PaperSim::new(PaperSimConfig {
        dt: 0.02,
        forward_speed: 10.0,
        process_noise: process.clone(),
        measurement_noise: measurement.clone(),
        faults: vec![fault],
        dither: None,
        seed: 9,
    })
    .unwrap();
    let data: Vec<PaperSample> = (0..1000).map(|_| sim.step()).collect();
    let n = BankNoise::nominal(&process, &measurement);
    let m = PaperHeli::new(paper_params(10.0), 0.02);
    let (u, a) = (UkfParams::default(), AdaptationParams::default());
    let mut ukf =
        Ukf::<_, 5, 3, 11>::new(m.clone(), u, x0(), kalman_p0(), n.kalman_q(), n.kalman_r());
    let mut kf_ukf = KfUkf::<_, 5, 3, 11>::new(
        m.clone(),
        u,
        a,
        SlaveKfParams::default(),
        x0(),
        kalman_p0(),
        n.kalman_q(),
        n.kalman_r(),
    );
    let mut mit_ukf = MitUkf::<_, 5, 3, 11>::new(
        m.clone(),
        u,
        a,
        x0(),
        kalman_p0(),
        n.kalman_q(),
        n.kalman_r(),
    );
    let mut esmf = Esmf::new(
        m.clone(),
        EsmfParams::default(),
        x0(),
        set_p0(),
        n.set_q(),
        n.set_r(),
    );
    let mut mit_esmf = MitEsmf::new(
        m,
        EsmfParams::default(),
        a,
        x0(),
        set_p0(),
        n.set_q(),
        n.set_r(),
    );
    let counts = [
        (
            "ukf",
            count(|| data.iter().for_each(|s| ukf.try_step(&s.u, &s.y).unwrap())),
        ),
        (
            "kf-ukf",
            count(|| {
                data.iter()
                    .for_each(|s| kf_ukf.try_step(&s.u, &s.y).unwrap())
            }),
        ),
        (
            "mit-ukf",
            count(|| {
                data.iter()
                    .for_each(|s| mit_ukf.try_step(&s.u, &s.y).unwrap())
            }),
        ),
        (
            "esmf",
            count(|| {
                data.iter()
                    .for_each(|s| assert!(esmf.try_step(&s.u, &s.y).is_ok()))
            }),
        ),
        (
            "mit-esmf",
            count(|| {
                data.iter()
                    .for_each(|s| assert!(mit_esmf.try_step(&s.u, &s.y).is_ok()))
            }),
        ),
    ];
    // The counter itself works: a Vec allocates.
    assert!(count(|| drop(std::hint::black_box(vec![1u8; 64]))) >= 1);
    for (name, c) in counts {
        assert_eq!(c, 0, "{name}: {c} heap allocations in 1000 steps");
    }
}

/// The vehicle filters: quad X with a_z (n = 11, m = 4) and an octocopter-sized model
/// (8 actuators, n = 19), both filters, no heap allocation per step.
#[test]
fn vehicle_filter_steps_allocate_nothing() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    use ahcmon::estimate::vehicle::{FilterPair, FilterSetup, VehicleFilters};
    use ahcmon::sim::vehicle::{ModelMismatch, VehicleSim, VehicleSimConfig};
    use ahcmon::telemetry::Profile;
    let profile = Profile::resolve("quad-x").unwrap();
    let mut sim = VehicleSim::new(VehicleSimConfig {
        dt: 0.02,
        profile: profile.clone(),
        mismatch: ModelMismatch {
            damping: 1.0,
            effectiveness: 1.0,
        },
        gusts: None,
        dither: None,
        manoeuvres: vec![],
        faults: vec![],
        gyro_noise: 0.003,
        az_noise: 0.3,
        bounded_noise: false,
        seed: 1,
    })
    .unwrap();
    let samples: Vec<_> = (0..1000).map(|_| sim.step()).collect();
    let mut quad = FilterPair::<11, 4, 23>::new(FilterSetup::from_profile(&profile, 0.02).unwrap());
    let mut reseated = 0;
    let n = count(|| {
        for (k, s) in samples.iter().enumerate() {
            // One sample in five lost: a coast (prediction only) instead of a step; now and
            // then an outage, after which the rates are re-measured.
            if k % 100 == 50 {
                quad.reseat(&[s.y[0], s.y[1], s.y[2]], 25.0);
            }
            let r = if k % 5 == 4 {
                quad.coast(&s.u[..4])
            } else {
                quad.step(&s.u[..4], &s.y[..4])
            };
            assert!(r.iter().all(|r| r.is_ok()));
            // A fault "decided" at step 300 and in force to step 700: the MIT-UKF identifies
            // (holds its AHC noise, tests the innovation mean) from step 450.
            if k == 300 {
                quad.forget(1);
            }
            quad.set_fault_in_force((300..700).contains(&k));
            if k == 500 {
                assert!(quad.ukf.identifying());
            }
            // Reseated from the diagnosis on every step of the identification (at the healthy
            // point: the simulated quad has no fault, and a reseat away from it would end the
            // hold).
            if quad.awaits_identification(1) {
                reseated += 1;
                quad.hold_class(
                    1,
                    Some(Identified {
                        kind: IdentifiedKind::Gain,
                        gamma: 1.0,
                        gamma_std: 0.01,
                        delta: 0.0,
                        delta_std: 0.013,
                        tolerance: 0.15,
                    }),
                );
            }
        }
    });
    assert_eq!(
        n, 0,
        "quad: {n} allocations in 1000 steps, coasts and reseats"
    );
    assert!(
        reseated >= 150,
        "the identification was followed on {reseated} steps only"
    );
    // Rates-only detectors with the set filter's a_z row (a helicopter's identified model):
    // a_z beside the rates, every fifth sample without it.
    let mut rates_only = profile.clone();
    rates_only.model.measure_az = false;
    let p = profile.rate_params();
    let mut row =
        FilterPair::<11, 3, 23>::new(FilterSetup::from_profile(&rates_only, 0.02).unwrap());
    row.set_vertical(Some((&p.vertical, p.vertical_offset)));
    let bounds = [[0.05, 0.05, 0.05, 1.0]; ahcmon::estimate::ahc_set::LAGS.len()];
    row.set_residual_bounds(bounds, [0.5; ahcmon::model::MAX_ACTUATORS]);
    assert_eq!(row.set_rows(), 4);
    let n = count(|| {
        for (k, s) in samples.iter().enumerate() {
            let y = if k % 5 == 4 { &s.y[..3] } else { &s.y[..4] };
            assert!(row.step(&s.u[..4], y).iter().all(|r| r.is_ok()));
        }
    });
    assert_eq!(n, 0, "the set's a_z row: {n} allocations in 1000 steps");
    assert!(row.guaranteed(1).output_bounds.is_some());
    // Eight actuators: the quad's motors twice over (an X8-like coaxial layout).
    let mut octo = profile.clone();
    let mut extra = octo.actuators.clone();
    for (i, a) in extra.iter_mut().enumerate() {
        a.name = format!("motor{}", i + 5);
        a.channel = (i + 5) as u8;
    }
    octo.actuators.extend(extra);
    let mut eight = FilterPair::<19, 4, 39>::new(FilterSetup::from_profile(&octo, 0.02).unwrap());
    let n = count(|| {
        for s in &samples[..200] {
            let mut u = [0.0; 8];
            u[..4].copy_from_slice(&s.u[..4]);
            u[4..].copy_from_slice(&s.u[..4]);
            let _ = eight.step(&u, &s.y[..4]);
        }
    });
    assert_eq!(n, 0, "octo: {n} allocations in 200 steps");
}

/// The diagnosis' fit runs on every step of a decided fault's identification (see
/// `VehicleFilters::hold_class`): the whitened fit and the change search allocate nothing.
#[test]
fn the_change_tests_fits_allocate_nothing() {
    use ahcmon::diagnose::change::ChangeTest;
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let effects = vec![
        [1.0, 0.0, 0.2, 0.0],
        [0.0, 1.0, -0.2, 0.0],
        [-0.5, -0.5, 1.0, 0.0],
    ];
    let mut test = ChangeTest::new(effects, [1.0; 4], 3, 300, 10, 600);
    // A slow wind-like residual (deterministic), then actuator 0's output 0.1 low.
    let mut wind = [0.0f64; 3];
    for k in 0..1500 {
        let t = k as f64 * 0.02;
        let u = [
            0.5 + 0.04 * (7.0 * t).sin(),
            0.5,
            0.5 + 0.03 * (3.0 * t).cos(),
        ];
        let mut r = [0.0; 4];
        for (i, w) in wind.iter_mut().enumerate() {
            *w = 0.97 * *w + 0.01 * ((k * (i + 3)) as f64 * 0.7).sin();
            r[i] = *w;
        }
        let changed = k >= 1300;
        if changed {
            r[0] -= 0.1;
            r[2] -= 0.02;
        }
        test.push(t, &r, &u, !changed);
    }
    assert!(test.colour_learned());
    let mut fits = 0;
    let n = count(|| {
        for k in 0..1000 {
            fits += usize::from(test.whitened_gain_or_offset(k % 3, 200).is_some());
            fits += usize::from(test.evaluate().is_some());
        }
    });
    assert_eq!(n, 0, "{n} allocations in 1000 fits and searches");
    assert_eq!(fits, 2000, "a fit or a reading missing");
}
