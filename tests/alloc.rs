//! The estimator step is the hot path: a counting global allocator shows that 1000 steps of each
//! filter allocate nothing on the heap.

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

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn count<F: FnMut()>(mut f: F) -> u64 {
    let before = ALLOCS.load(Ordering::SeqCst);
    f();
    ALLOCS.load(Ordering::SeqCst) - before
}

#[test]
fn a_thousand_steps_of_each_filter_allocate_nothing() {
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
