//! Criterion benchmarks of the engine, on the scenes of `benches/scenes/` (written by
//! `augmpm.bench`; the Python test suite checks they match it):
//!
//! - `fig1/{naive,augmented}`: 100 steps of the paper's Fig. 1 scene (~1,500 particles);
//! - `dam_break_{128,256}/{method}/{threads}t`: steps of the tilted-tank dam break, reported as
//!   particle-steps per second (`AUGMPM_BENCH_512=1` adds the ~530k-particle size).
//!
//! Run with `cargo bench -p augmpm-core`; `augmpm bench` measures the same cases end to end,
//! with memory, the stage split and the output cost.

use augmpm_core::{Method, Scene, Simulation};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use std::path::Path;
use std::time::Duration;

fn scene(name: &str) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../benches/scenes").join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    Scene::from_json(&text).unwrap_or_else(|e| panic!("{}: {e:?}", path.display()))
}

fn simulation(scene: &Scene, method: Method, threads: usize) -> Simulation<2> {
    let (mut sim, _) = scene.build(method).expect("bench scenes build");
    sim.set_threads(threads).expect("threads start");
    sim.advance(3).expect("warm-up steps");
    sim
}

fn fig1(c: &mut Criterion) {
    let scene = scene("fig1_fluid_incline_noslip.json");
    let mut group = c.benchmark_group("fig1");
    group.sample_size(10).measurement_time(Duration::from_secs(5));
    for (name, method) in [("naive", Method::Naive), ("augmented", Method::Augmented)] {
        let mut sim = simulation(&scene, method, 1);
        group.throughput(Throughput::Elements(100));
        group.bench_function(name, |b| b.iter(|| sim.advance(100).expect("fig1 steps")));
    }
    group.finish();
}

fn dam_break(c: &mut Criterion) {
    let mut sizes = vec![(128, 50), (256, 10)];
    if std::env::var_os("AUGMPM_BENCH_512").is_some() {
        sizes.push((512, 2));
    }
    for (resolution, steps) in sizes {
        let scene = scene(&format!("dam_break_{resolution}.json"));
        let mut group = c.benchmark_group(format!("dam_break_{resolution}"));
        group.sample_size(10).measurement_time(Duration::from_secs(5));
        for (name, method) in [("naive", Method::Naive), ("augmented", Method::Augmented)] {
            for threads in [1, 2] {
                let mut sim = simulation(&scene, method, threads);
                group.throughput(Throughput::Elements((sim.state.particles.len() * steps) as u64));
                group.bench_function(BenchmarkId::new(name, format!("{threads}t")), |b| {
                    b.iter(|| sim.advance(steps as u64).expect("dam break steps"))
                });
            }
        }
        group.finish();
    }
}

criterion_group!(benches, fig1, dam_break);
criterion_main!(benches);
