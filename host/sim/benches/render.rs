//! Frame rate of the simulated camera (target: 640 x 480 at >= 30 fps on one core, i.e. <= 33 ms per frame).
use criterion::{criterion_group, criterion_main, Criterion};
use nusense_sim::{Contact, Renderer, Scene, SensorModel};

fn render(c: &mut Criterion) {
    let mut group = c.benchmark_group("render_640x480");
    let renderer = Renderer::new(SensorModel::real(640, 480)).expect("the real sensor model is valid");
    let rest = Scene::rest();
    let press = Scene::with_contact(Contact::sphere(5.0, [2.0, -1.0], 6.0));
    let edge = Scene::with_contact(Contact::edge(20.0, 1.0, 30.0, [0.0, 0.0], 8.0));
    let mut seed = 0u64;
    for (name, scene) in [("rest", &rest), ("sphere_6N", &press), ("edge_8N", &edge)] {
        group.bench_function(name, |b| {
            b.iter(|| {
                seed += 1;
                renderer.render(scene, [100.0; 4], seed).expect("valid scene")
            })
        });
    }
    let mut model = SensorModel::real(640, 480);
    model.jpeg_quality = Some(90);
    let jpeg = Renderer::new(model).expect("valid model");
    group.bench_function("sphere_6N_jpeg90", |b| {
        b.iter(|| {
            seed += 1;
            jpeg.render(&press, [100.0; 4], seed).expect("valid scene")
        })
    });
    group.finish();
    c.bench_function("renderer_new_640x480", |b| {
        b.iter(|| Renderer::new(SensorModel::real(640, 480)).expect("valid"))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(std::time::Duration::from_secs(3));
    targets = render
}
criterion_main!(benches);
