//! A synthetic box room sampled at random — floor, three walls and a table, 8 × 6 × 3 m — well
//! constrained in all six degrees of freedom: what the ICP's tests and its criterion benchmark
//! register (`benches/compare_small_gicp.py` draws the same shapes for small_gicp).

use nalgebra::Point3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// `n` points of the room, the surfaces taking turns, drawn from `seed`.
pub fn box_room(n: usize, seed: u64) -> Vec<Point3<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|k| {
            let (a, b): (f64, f64) = (rng.random_range(0.0..1.0), rng.random_range(0.0..1.0));
            match k % 6 {
                0 => Point3::new(8.0 * a, 6.0 * b, 0.0),
                1 => Point3::new(8.0 * a, 0.0, 3.0 * b),
                2 => Point3::new(0.0, 6.0 * a, 3.0 * b),
                3 => Point3::new(8.0 * a, 6.0, 3.0 * b),
                4 => Point3::new(2.0 + 1.5 * a, 2.0 + 0.8 * b, 0.75),
                _ => Point3::new(2.0, 2.0 + 0.8 * a, 0.75 * b),
            }
        })
        .collect()
}
