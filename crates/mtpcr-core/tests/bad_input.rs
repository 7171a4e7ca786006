//! Every kind of bad input gives a clear error that names the problem, never a panic.

use mtpcr_core::io::read_ply;
use mtpcr_core::{register, synthetic, Config, Error, Method, PointCloud};

fn clouds() -> Vec<PointCloud> {
    synthetic::three_views(31, 2000).clouds
}

fn quick() -> Config {
    Config {
        generations: 1,
        population_size: 8,
        seed: Some(1),
        ..Config::default()
    }
}

#[test]
fn empty_cloud() {
    let mut c = clouds();
    c[1] = PointCloud::new(vec![]);
    let e = register(&c, &quick(), None).unwrap_err();
    assert!(matches!(e, Error::EmptyCloud { .. }), "{e}");
    assert!(
        e.to_string().contains("cloud 2") && e.to_string().contains("empty"),
        "{e}"
    );
}

#[test]
fn too_few_points() {
    let mut c = clouds();
    c[2] = PointCloud::new(vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let e = register(&c, &quick(), None).unwrap_err();
    assert!(matches!(e, Error::TooFewPoints { points: 3, .. }), "{e}");
    assert!(e.to_string().contains("cloud 3"), "{e}");
}

#[test]
fn nan_and_infinite_coordinates() {
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut c = clouds();
        let mut pts = c[0].points().to_vec();
        pts[17][2] = bad;
        c[0] = PointCloud::new(pts);
        let e = register(&c, &quick(), None).unwrap_err();
        assert!(
            matches!(e, Error::NonFiniteCoordinate { index: 17, .. }),
            "{e}"
        );
        assert!(
            e.to_string().contains("cloud 1") && e.to_string().contains("point 17"),
            "{e}"
        );
    }
}

#[test]
fn all_points_identical() {
    let mut c = clouds();
    c[0] = PointCloud::new(vec![[0.3, 0.3, 0.3]; 500]);
    let e = register(&c, &quick(), None).unwrap_err();
    assert!(matches!(e, Error::DegenerateCloud { .. }), "{e}");
}

/// A point at 1e308 or a whole cloud scaled by 1e300 used to give NaN transforms; now an error
/// names the cloud and the point.
#[test]
fn finite_but_huge_coordinates() {
    let mut c = clouds();
    let mut pts = c[1].points().to_vec();
    pts[42][0] = 1e308;
    c[1] = PointCloud::new(pts);
    let e = register(&c, &quick(), None).unwrap_err();
    assert!(
        matches!(e, Error::CoordinateTooLarge { index: 42, .. }),
        "{e}"
    );
    assert!(
        e.to_string().contains("cloud 2") && e.to_string().contains("point 42"),
        "{e}"
    );

    let scaled = |s: f64| -> Vec<PointCloud> {
        clouds()
            .iter()
            .map(|c| PointCloud::new(c.points().iter().map(|p| p.map(|v| v * s)).collect()))
            .collect()
    };
    let e = register(&scaled(1e300), &quick(), None).unwrap_err();
    assert!(
        matches!(e, Error::CoordinateTooLarge { index: 0, .. }),
        "{e}"
    );
    // Just under the limit every method runs, with finite costs and transforms (at 1e50 the
    // fast distance field's f32 values overflowed: NaN costs, and MFEA panicked).
    let largest = clouds()
        .iter()
        .flat_map(|c| c.points().iter().flatten().map(|v| v.abs()))
        .fold(0.0, f64::max);
    let near_limit = scaled(0.99 * mtpcr_core::cloud::MAX_COORDINATE / largest);
    for method in [Method::Mtpcr, Method::Mfea, Method::Gmfea] {
        let r = register(&near_limit, &Config { method, ..quick() }, None).unwrap();
        assert!(
            r.history.iter().flatten().all(|v| v.is_finite()),
            "{method:?}: {:?}",
            r.history
        );
        for e in &r.edges {
            assert!(
                e.t_target_source.iter().all(|v| v.is_finite()),
                "{method:?}: {}",
                e.t_target_source
            );
        }
    }
}

#[test]
fn collinear_cloud() {
    let mut c = clouds();
    c[2] = PointCloud::new(
        (0..300)
            .map(|i| {
                let t = i as f64 * 0.01;
                [0.2 + t, -0.1 + 2.0 * t, 0.5 - 0.3 * t]
            })
            .collect(),
    );
    let e = register(&c, &quick(), None).unwrap_err();
    assert!(matches!(e, Error::CollinearCloud { .. }), "{e}");
    assert!(
        e.to_string().contains("cloud 3") && e.to_string().contains("line"),
        "{e}"
    );
}

#[test]
fn config_values_out_of_range_name_the_field() {
    let base = quick();
    let cases: Vec<(&str, Config)> = vec![
        (
            "population_size",
            Config {
                population_size: 2,
                ..base.clone()
            },
        ),
        (
            "sample_ratio",
            Config {
                sample_ratio: 0.0,
                ..base.clone()
            },
        ),
        (
            "sample_ratio",
            Config {
                sample_ratio: 1.5,
                ..base.clone()
            },
        ),
        (
            "sample_ratio",
            Config {
                sample_ratio: f64::NAN,
                ..base.clone()
            },
        ),
        (
            "p_intra",
            Config {
                p_intra: -0.1,
                ..base.clone()
            },
        ),
        (
            "p_inter",
            Config {
                p_inter: 2.0,
                ..base.clone()
            },
        ),
        (
            "top_ratio",
            Config {
                top_ratio: 0.0,
                ..base.clone()
            },
        ),
        (
            "scale_factor",
            Config {
                scale_factor: 0.0,
                ..base.clone()
            },
        ),
        (
            "sbx_eta_start",
            Config {
                sbx_eta_start: -1.0,
                ..base.clone()
            },
        ),
        (
            "sbx_eta_end",
            Config {
                sbx_eta_end: f64::INFINITY,
                ..base.clone()
            },
        ),
        (
            "alpha",
            Config {
                alpha: -0.05,
                ..base.clone()
            },
        ),
        (
            "aiding_cap_ratio",
            Config {
                aiding_cap_ratio: 0.0,
                ..base.clone()
            },
        ),
        (
            "generations",
            Config {
                generations: usize::MAX,
                ..base.clone()
            },
        ),
        (
            "num_threads",
            Config {
                num_threads: 100_000,
                ..base.clone()
            },
        ),
    ];
    for (field, config) in cases {
        let e = register(&clouds(), &config, None).unwrap_err();
        match &e {
            Error::InvalidConfig { field: f, .. } => assert_eq!(*f, field, "{e}"),
            other => panic!("{field}: expected a config error, got {other}"),
        }
        assert!(e.to_string().contains(field), "{e}");
    }
}

#[test]
fn unreadable_and_malformed_ply_files_name_the_file() {
    let dir = std::env::temp_dir().join(format!("mtpcr-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let missing = dir.join("missing.ply");
    let e = read_ply(&missing).unwrap_err();
    assert!(
        matches!(e, Error::Io { .. }) && e.to_string().contains("missing.ply"),
        "{e}"
    );

    let garbage = dir.join("garbage.ply");
    std::fs::write(&garbage, [0u8, 159, 146, 150, 10, 1, 2]).unwrap();
    let e = read_ply(&garbage).unwrap_err();
    assert!(
        matches!(e, Error::MalformedFile { .. }) && e.to_string().contains("garbage.ply"),
        "{e}"
    );

    let bad_number = dir.join("bad_number.ply");
    std::fs::write(
        &bad_number,
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 five 6\n",
    )
    .unwrap();
    let e = read_ply(&bad_number).unwrap_err();
    assert!(e.to_string().contains("bad_number.ply"), "{e}");

    let dir_as_file = read_ply(&dir).unwrap_err();
    assert!(
        dir_as_file.to_string().contains(&dir.display().to_string()),
        "{dir_as_file}"
    );
}
