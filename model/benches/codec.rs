//! Keyframe cloud codec on the real Kinect frame: encode and decode throughput (criterion
//! reports MB/s of raw float32 xyz) at 1 cm.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use sgm_model::pcd::read_pcd;
use sgm_model::wire::cloud_codec::{decode, encode};
use std::hint::black_box;

fn codec(c: &mut Criterion) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/clouds/kinect_frame_20121214T142255.814212.pcd");
    let Ok(bytes) = std::fs::read(&path) else {
        eprintln!("{} missing: ../shared must sit beside the repository", path.display());
        return;
    };
    let Ok(points) = read_pcd(&bytes).and_then(|c| c.finite_points()) else { return };
    let Ok(encoded) = encode(&points, 0.01) else { return };
    println!("kinect frame: {} points, {:.3} bytes/point at 1 cm", points.len(), encoded.bytes_per_point());
    let mut group = c.benchmark_group("cloud_codec_1cm");
    group.throughput(Throughput::Bytes(points.len() as u64 * 12));
    group.bench_function("encode", |b| b.iter(|| encode(black_box(&points), 0.01)));
    group.bench_function("decode", |b| b.iter(|| decode(black_box(&encoded.bytes))));
    group.finish();
}

criterion_group!(benches, codec);
criterion_main!(benches);
