//! Seeded synthetic three-view problems: an asymmetric bumpy shape, three overlapping partial
//! views sampled independently (no shared points), each moved by a random rigid motion.
//! Used by the demo and by the tests that must run without data.

use crate::cloud::PointCloud;
use crate::se3::{invert_rigid, random_rigid, Transform};
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// A synthetic problem and its ground truth.
#[derive(Clone, Debug)]
pub struct SyntheticProblem {
    /// The three views, each in its own frame.
    pub clouds: Vec<PointCloud>,
    /// `[T12, T23, T31]` (T_ij maps view i into view j's frame).
    pub ground_truth: Vec<Transform>,
}

/// Size of the shape (about the bounding-box side), in metres: bunny-like.
const SHAPE_SIZE: f64 = 0.15;

struct Bump {
    centre: [f64; 3],
    height: f64,
    width: f64,
}

fn unit_vector<R: Rng + ?Sized>(rng: &mut R) -> [f64; 3] {
    loop {
        let v: [f64; 3] = [
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
        ];
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if n > 1e-9 {
            return [v[0] / n, v[1] / n, v[2] / n];
        }
    }
}

/// Views of a seeded shape taken from all around it: `count` views looking from directions
/// `360 / count` degrees apart around a tilted axis (neighbours overlap more the more views
/// there are), each of `points_per_view` points and moved by a random rigid motion.
#[derive(Clone, Debug)]
pub struct SyntheticViews {
    /// The views, each in its own frame.
    pub clouds: Vec<PointCloud>,
    /// Each view's ground-truth view-to-world pose (`x_world = pose x_view`).
    pub poses: Vec<Transform>,
}

/// `count` views around a seeded shape (see [`SyntheticViews`]).
pub fn views_around(seed: u64, count: usize, points_per_view: usize) -> SyntheticViews {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7669_6577);
    let surface = shape(&mut rng);
    let directions: Vec<[f64; 3]> = (0..count)
        .map(|i| {
            let a = (i as f64 * 360.0 / count as f64 + rng.random_range(-5.0..5.0)).to_radians();
            let e: f64 = rng.random_range(-0.3..0.3);
            [a.cos() * e.cos(), e.sin(), a.sin() * e.cos()]
        })
        .collect();
    let motions: Vec<Transform> = (0..count)
        .map(|_| random_rigid(&mut rng, SHAPE_SIZE))
        .collect();
    let clouds = directions
        .iter()
        .zip(&motions)
        .map(|(v, m)| view(&surface, *v, points_per_view, &mut rng).transformed(m))
        .collect();
    SyntheticViews {
        clouds,
        poses: motions.iter().map(invert_rigid).collect(),
    }
}

/// A seeded closed surface: `surface(u)` is the point in unit direction `u`.
fn shape(rng: &mut ChaCha8Rng) -> impl Fn([f64; 3]) -> [f64; 3] {
    let bumps: Vec<Bump> = (0..66)
        .map(|i| match i {
            0..6 => Bump {
                centre: unit_vector(rng),
                height: rng.random_range(0.4..0.7),
                width: rng.random_range(0.15..0.25),
            },
            6..14 => Bump {
                centre: unit_vector(rng),
                height: rng.random_range(-0.2..0.45),
                width: rng.random_range(0.25..0.5),
            },
            _ => Bump {
                centre: unit_vector(rng),
                height: rng.random_range(-0.08..0.12),
                width: rng.random_range(0.08..0.2),
            },
        })
        .collect();
    let axes = [1.0, 0.6, 0.42];
    move |u: [f64; 3]| -> [f64; 3] {
        let mut r = 1.0 + 0.3 * u[0] + 0.2 * u[1] + 0.15 * u[0] * u[2];
        for b in &bumps {
            let d2: f64 = (0..3).map(|k| (u[k] - b.centre[k]).powi(2)).sum();
            r += b.height * (-d2 / (b.width * b.width)).exp();
        }
        std::array::from_fn(|k| 0.5 * SHAPE_SIZE * axes[k] * r * u[k] / 1.3)
    }
}

/// The points of `surface` facing the viewer at direction `v` (a bit beyond a hemisphere).
fn view(
    surface: &impl Fn([f64; 3]) -> [f64; 3],
    v: [f64; 3],
    points: usize,
    rng: &mut ChaCha8Rng,
) -> PointCloud {
    let mut pts = Vec::with_capacity(points);
    while pts.len() < points {
        let u = unit_vector(rng);
        if u[0] * v[0] + u[1] * v[1] + u[2] * v[2] > -0.2 {
            pts.push(surface(u));
        }
    }
    PointCloud::new(pts)
}

/// Three views of about `points_per_view` points each of a seeded shape; the views overlap
/// pairwise by about 40 to 70 %.
pub fn three_views(seed: u64, points_per_view: usize) -> SyntheticProblem {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // A few large lobes and many small bumps: features at several scales, as real objects have.
    // Six narrow protrusions (ears, a nose: something every view sees), a few large lobes
    // and many small bumps: features at several scales, as real objects have.
    let bumps: Vec<Bump> = (0..66)
        .map(|i| match i {
            0..6 => Bump {
                centre: unit_vector(&mut rng),
                height: rng.random_range(0.4..0.7),
                width: rng.random_range(0.15..0.25),
            },
            6..14 => Bump {
                centre: unit_vector(&mut rng),
                height: rng.random_range(-0.2..0.45),
                width: rng.random_range(0.25..0.5),
            },
            _ => Bump {
                centre: unit_vector(&mut rng),
                height: rng.random_range(-0.08..0.12),
                width: rng.random_range(0.08..0.2),
            },
        })
        .collect();
    let axes = [1.0, 0.6, 0.42];
    // An egg thicker towards +x and +y, skewed in x-z, with bumps: no rotation maps it onto
    // itself, so no view can hide in a symmetry.
    let surface = |u: [f64; 3]| -> [f64; 3] {
        let mut r = 1.0 + 0.3 * u[0] + 0.2 * u[1] + 0.15 * u[0] * u[2];
        for b in &bumps {
            let d2: f64 = (0..3).map(|k| (u[k] - b.centre[k]).powi(2)).sum();
            r += b.height * (-d2 / (b.width * b.width)).exp();
        }
        std::array::from_fn(|k| 0.5 * SHAPE_SIZE * axes[k] * r * u[k] / 1.3)
    };
    // Viewing directions about 60 degrees apart around a tilted axis (views 1 and 3 are
    // about 120 degrees apart and overlap least).
    let views: [[f64; 3]; 3] = std::array::from_fn(|i| {
        let a = (i as f64 * 60.0 + rng.random_range(-8.0..8.0)).to_radians();
        let e: f64 = rng.random_range(-0.3..0.3);
        [a.cos() * e.cos(), e.sin(), a.sin() * e.cos()]
    });
    let motions: [Transform; 3] = std::array::from_fn(|_| random_rigid(&mut rng, SHAPE_SIZE));
    let clouds: Vec<PointCloud> = (0..3)
        .map(|i| {
            let v = views[i];
            let mut pts = Vec::with_capacity(points_per_view);
            // Visible: the radial direction faces the viewer (a bit beyond the hemisphere).
            while pts.len() < points_per_view {
                let u = unit_vector(&mut rng);
                if u[0] * v[0] + u[1] * v[1] + u[2] * v[2] > -0.2 {
                    pts.push(surface(u));
                }
            }
            PointCloud::new(pts).transformed(&motions[i])
        })
        .collect();
    let ground_truth = (0..3)
        .map(|i| motions[(i + 1) % 3] * invert_rigid(&motions[i]))
        .collect();
    SyntheticProblem {
        clouds,
        ground_truth,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn views_around_are_seeded_and_posed() {
        let a = views_around(2, 5, 500);
        assert_eq!(a.clouds.len(), 5);
        assert_eq!(a.clouds, views_around(2, 5, 500).clouds);
        assert_ne!(a.clouds, views_around(3, 5, 500).clouds);
        // Every view, put in the world frame, lies on the same shape: near view 0's points.
        let world: Vec<PointCloud> = a
            .clouds
            .iter()
            .zip(&a.poses)
            .map(|(c, p)| c.transformed(p))
            .collect();
        let (lo, hi) = world[1].bounds();
        let (lo0, hi0) = world[0].bounds();
        for k in 0..3 {
            assert!((lo[k] - lo0[k]).abs() < 0.06 && (hi[k] - hi0[k]).abs() < 0.06);
        }
    }

    #[test]
    fn views_are_seeded_and_the_ground_truth_closes_the_loop() {
        let a = three_views(3, 2000);
        let b = three_views(3, 2000);
        assert_eq!(a.clouds, b.clouds);
        assert_eq!(a.clouds[0].len(), 2000);
        let [t12, t23, t31] = [a.ground_truth[0], a.ground_truth[1], a.ground_truth[2]];
        assert!((t31 * t23 * t12 - Transform::identity()).norm() < 1e-12);
        assert_ne!(three_views(4, 2000).clouds, a.clouds);
    }
}
