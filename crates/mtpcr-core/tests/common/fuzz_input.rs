//! The decoder of the `register` fuzz target (fuzz/fuzz_targets/register.rs), shared with its
//! regression tests (tests/fuzz_register.rs): any bytes become 2 to 4 clouds of a few dozen
//! points (copies of one random shape moved by rigid motions, random points, or degenerate
//! ones: identical points, lines, planes, repeated points, far-apart clusters, extreme scales
//! and offsets), or for one input in eight 3 to 10 scans of a few hundred points of two
//! synthetic shapes in no known order (so that pairs verify and the placement of scans in
//! no known order is fuzzed; see `scene`), and a tiny config (population 4-8, generations 0-2, one restart, refinement
//! 0-2 iterations, 0-3 feature hypotheses, sample_ratio from the bytes, any method, order,
//! sampling and search). Once the input bytes run out, a generator seeded by them supplies
//! the rest, so every input gives full clouds.
//!
//! The regression tests replay inputs through this decoder: change it only together with
//! them (print an input's clouds with `MTPCR_FUZZ_PRINT=1` and pin them first).
#![allow(dead_code)]

use mtpcr_core::synthetic::views_around;
use mtpcr_core::{register, Config, Method, Order, PointCloud, Sampling, SearchMethod};

/// The input bytes, then a xorshift generator seeded by them.
struct Source<'a> {
    bytes: &'a [u8],
    state: u64,
}

impl<'a> Source<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for &b in bytes {
            state = (state ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
        Source {
            bytes,
            state: state | 1,
        }
    }

    fn byte(&mut self) -> u8 {
        if let Some((&b, rest)) = self.bytes.split_first() {
            self.bytes = rest;
            return b;
        }
        self.state ^= self.state << 13;
        self.state ^= self.state >> 7;
        self.state ^= self.state << 17;
        (self.state >> 32) as u8
    }

    /// A value in -1..1 from two bytes.
    fn unit(&mut self) -> f64 {
        let v = i16::from_le_bytes([self.byte(), self.byte()]);
        f64::from(v) / 32768.0
    }

    fn point(&mut self) -> [f64; 3] {
        [self.unit(), self.unit(), self.unit()]
    }
}

/// A rotation about a random axis by a random angle, and a random translation.
fn motion(src: &mut Source<'_>) -> ([[f64; 3]; 3], [f64; 3]) {
    let mut axis = src.point();
    let norm = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    if norm < 1e-3 {
        axis = [0.0, 0.0, 1.0];
    } else {
        axis = axis.map(|v| v / norm);
    }
    let angle = src.unit() * std::f64::consts::PI;
    let (s, c) = angle.sin_cos();
    let [x, y, z] = axis;
    let t = 1.0 - c;
    let r = [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ];
    (r, src.point())
}

fn apply((r, t): &([[f64; 3]; 3], [f64; 3]), p: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + t[i])
}

/// One cloud of 8 to 71 points; `shape` is the common shape the overlapping kinds copy.
fn cloud(src: &mut Source<'_>, shape: &[[f64; 3]]) -> PointCloud {
    let n = 8 + usize::from(src.byte() % 64);
    let kind = src.byte() % 12;
    let mut points: Vec<[f64; 3]> = match kind {
        // A moved copy of part of the common shape (the usual, overlapping case).
        0..=4 => {
            let m = motion(src);
            let skip = usize::from(src.byte()) % (shape.len() / 2);
            shape
                .iter()
                .skip(skip)
                .take(n)
                .map(|p| apply(&m, p))
                .collect()
        }
        // Random points.
        5 | 6 => (0..n).map(|_| src.point()).collect(),
        // All points identical.
        7 => vec![src.point(); n],
        // A line, exact or with a tiny offset.
        8 => {
            let (o, d, e) = (src.point(), src.point(), f64::from(src.byte() % 4) * 1e-9);
            (0..n)
                .map(|i| {
                    let t = i as f64 / n as f64;
                    let w = src.unit() * e;
                    std::array::from_fn(|k| o[k] + t * d[k] + w)
                })
                .collect()
        }
        // A plane.
        9 => {
            let (o, a, b) = (src.point(), src.point(), src.point());
            (0..n)
                .map(|_| {
                    let (u, v) = (src.unit(), src.unit());
                    std::array::from_fn(|k| o[k] + u * a[k] + v * b[k])
                })
                .collect()
        }
        // Few distinct points, repeated.
        10 => {
            let distinct: Vec<[f64; 3]> = (0..1 + src.byte() % 4).map(|_| src.point()).collect();
            (0..n).map(|i| distinct[i % distinct.len()]).collect()
        }
        // Two tight clusters far apart.
        _ => {
            let far = 10f64.powi(i32::from(src.byte() % 12));
            (0..n)
                .map(|i| {
                    let p = src.point().map(|v| v * 1e-3);
                    if i % 2 == 0 {
                        p
                    } else {
                        [p[0] + far, p[1], p[2]]
                    }
                })
                .collect()
        }
    };
    // Sometimes an extreme scale or offset (the whole range of f64, both ways).
    match src.byte() % 16 {
        0 => {
            let scale = 10f64.powi(i32::from(src.byte()) * 616 / 255 - 308);
            points.iter_mut().for_each(|p| *p = p.map(|v| v * scale));
        }
        1 => {
            let offset = 10f64.powi(i32::from(src.byte() % 200) - 20);
            points.iter_mut().for_each(|p| p[0] += offset);
        }
        _ => {}
    }
    PointCloud::new(points)
}

fn config(src: &mut Source<'_>) -> Config {
    Config {
        method: [Method::Mtpcr, Method::Mfea, Method::Gmfea][usize::from(src.byte() % 3)],
        order: if src.byte() % 2 == 0 {
            Order::Auto
        } else {
            Order::Given
        },
        population_size: 4 + usize::from(src.byte() % 5),
        generations: usize::from(src.byte() % 3),
        sample_ratio: f64::from(src.byte()).max(1.0) / 255.0,
        sampling: if src.byte() % 2 == 0 {
            Sampling::Farthest
        } else {
            Sampling::Random
        },
        search: if src.byte() % 2 == 0 {
            SearchMethod::Fast
        } else {
            SearchMethod::Exact
        },
        two_way_aiding: src.byte() % 2 == 0,
        restarts: 1,
        refine_iterations: usize::from(src.byte() % 3),
        hypotheses: usize::from(src.byte() % 4),
        num_threads: 1,
        seed: Some(u64::from(src.byte())),
        ..Config::default()
    }
}

/// Scans in no known order whose pairs can be verified (the few dozen points of [`cloud`]
/// never give feature hypotheses, so the placement after the verification would go
/// unfuzzed): 3 to 7 views of one seeded synthetic shape and 0 to 3 of another (a group of
/// scans apart from the others; issue 23), in an order from the bytes, of 300 to 800 points
/// each; sometimes one of them replaced by a [`cloud`] (degenerate, random, ...).
fn scene(src: &mut Source<'_>, shape: &[[f64; 3]]) -> Vec<PointCloud> {
    let points = 300 + 100 * usize::from(src.byte() % 6);
    let first = 3 + usize::from(src.byte() % 5);
    let second = usize::from(src.byte() % 4);
    let (a, b) = (u64::from(src.byte()), 256 + u64::from(src.byte()));
    let mut clouds = views_around(a, first, points).clouds;
    // Views of another shape: at least three around it, so that they overlap each other.
    clouds.extend(
        views_around(b, second.max(3), points)
            .clouds
            .into_iter()
            .take(second),
    );
    // A random order (Fisher-Yates).
    for i in (1..clouds.len()).rev() {
        clouds.swap(i, usize::from(src.byte()) % (i + 1));
    }
    if src.byte() % 4 == 0 {
        let k = usize::from(src.byte()) % clouds.len();
        clouds[k] = cloud(src, shape);
    }
    clouds
}

/// The config and clouds of an input.
pub fn decode(data: &[u8]) -> (Config, Vec<PointCloud>) {
    let mut src = Source::new(data);
    let config = config(&mut src);
    let views = 2 + usize::from(src.byte() % 3);
    let shape: Vec<[f64; 3]> = (0..160).map(|_| src.point()).collect();
    let mut clouds: Vec<PointCloud> = (0..views).map(|_| cloud(&mut src, &shape)).collect();
    // Decided by a byte read after all the above, so that inputs which do not take this
    // branch decode as they did before it was added (the crashes pinned in
    // tests/fuzz_register.rs among them).
    if src.byte() % 8 == 0 {
        clouds = scene(&mut src, &shape);
    }
    (config, clouds)
}

/// Registers the input's clouds; panics if the engine panics or an `Ok` result has a
/// non-finite transform or pose, or a NaN best cost. An `Err` is fine (most degenerate inputs
/// give one).
pub fn check(data: &[u8]) {
    let (config, clouds) = decode(data);
    if std::env::var_os("MTPCR_FUZZ_PRINT").is_some() {
        eprintln!("config: {config:?}");
        for (i, c) in clouds.iter().enumerate() {
            eprintln!("cloud {}: {:?}", i + 1, c.points());
        }
    }
    if let Ok(r) = register(&clouds, &config, None) {
        assert!(
            r.history.iter().flatten().all(|v| !v.is_nan()),
            "a best cost is NaN: {:?}",
            r.history
        );
        for (k, e) in r.edges.iter().enumerate() {
            assert!(
                e.t_target_source.iter().all(|v| v.is_finite()),
                "edge {k} has a non-finite transform: {}",
                e.t_target_source
            );
        }
        for (k, pose) in r.poses.iter().enumerate() {
            if let Some(p) = pose {
                assert!(
                    p.iter().all(|v| v.is_finite()),
                    "pose {k} is not finite: {p}"
                );
            }
        }
    }
}
