//! Opens `view.html` (see `src/viewer.rs`) in headless Chromium and checks from a screenshot
//! that WebGL really drew the scans, in the "after" and in the "before" state.
//!
//! Needs Chromium: `chromium` or `chromium-browser` on the PATH, or the path of the binary
//! in `MTPCR_CHROMIUM` (Debian: `apt-get install -y chromium`). WebGL is drawn in software
//! (SwiftShader): `--headless --no-sandbox --disable-gpu --use-gl=swiftshader
//! --enable-unsafe-swiftshader`, and `--virtual-time-budget` lets the page's script finish
//! before the screenshot.
//!
//! Chromium is optional outside CI. Rust tests cannot report "skipped", so when no Chromium
//! is found this test checks nothing and passes, but first writes a `SKIPPED viewer_browser`
//! line straight to stderr (not through the test harness's output capture, so it shows in a
//! plain `cargo test` run); `scripts/test.sh` repeats it in a NOTE at the end. In CI (the
//! environment variable `CI` is `true` or `1`, as `.ci/run` sets it) a missing Chromium is a
//! failure instead, so the view stays tested there.
//!
//! The CLI has no library target, so `src/viewer.rs` (which uses nothing else of the CLI) is
//! compiled into this test with `#[path]`; its unit tests therefore run here too.

#[allow(dead_code)]
#[path = "../src/viewer.rs"]
mod viewer;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const WIDTH: usize = 1200;
const HEIGHT: usize = 800;
/// Part of the window that no overlay box covers at 1200x800 (panel top left, legend top
/// right, scale bar and help at the bottom): x from, x to, y from, y to.
const FREE: [usize; 4] = [380, 860, 150, 720];

/// Whether this run is in CI (`CI` is `true` or `1`), where a missing Chromium must fail.
fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v.eq_ignore_ascii_case("true") || v == "1")
}

/// The Chromium binary, if any.
fn chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("MTPCR_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    ["chromium", "chromium-browser"].iter().find_map(|name| {
        std::env::split_paths(&path)
            .map(|dir| dir.join(name))
            .find(|p| p.is_file())
    })
}

/// `n` points on a sphere of radius `r` around `c` (a Fibonacci lattice).
fn sphere(n: usize, c: [f64; 3], r: f64) -> Vec<[f64; 3]> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let s = (1.0 - y * y).sqrt();
            let t = golden * i as f64;
            [c[0] + r * s * t.cos(), c[1] + r * y, c[2] + r * s * t.sin()]
        })
        .collect()
}

/// Screenshots `page` (with `fragment`, e.g. `#before`) into `png`; returns RGB rows.
fn screenshot(
    browser: &Path,
    page: &Path,
    fragment: &str,
    png: &Path,
    profile: &Path,
) -> Vec<[u8; 3]> {
    let url = format!("file://{}{fragment}", page.display());
    let mut child = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--use-gl=swiftshader",
            "--enable-unsafe-swiftshader",
            "--hide-scrollbars",
            "--no-first-run",
            "--force-device-scale-factor=1",
            &format!("--user-data-dir={}", profile.display()),
            &format!("--screenshot={}", png.display()),
            &format!("--window-size={WIDTH},{HEIGHT}"),
            "--virtual-time-budget=5000",
            &url,
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {}: {e}", browser.display()));
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            panic!("{} took over 120 s for {url}", browser.display());
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    assert!(
        status.success(),
        "{} failed ({status}) on {url}",
        browser.display()
    );

    let file =
        std::fs::File::open(png).unwrap_or_else(|e| panic!("no screenshot {}: {e}", png.display()));
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(
        (info.width as usize, info.height as usize),
        (WIDTH, HEIGHT),
        "screenshot size"
    );
    let channels = info.line_size / WIDTH;
    assert!(channels >= 3, "{:?}", info.color_type);
    buf[..info.line_size * HEIGHT]
        .chunks(channels)
        .map(|p| [p[0], p[1], p[2]])
        .collect()
}

fn distance(a: [u8; 3], b: [u8; 3]) -> u32 {
    (0..3).map(|k| u32::from(a[k].abs_diff(b[k]))).sum()
}

/// Pixels of the free area unlike the background, and pixels close to each scan colour.
fn census(pixels: &[[u8; 3]], scans: usize) -> (usize, Vec<usize>) {
    let mut drawn = 0;
    let mut per_scan = vec![0; scans];
    for y in FREE[2]..FREE[3] {
        for x in FREE[0]..FREE[1] {
            let p = pixels[y * WIDTH + x];
            if distance(p, viewer::BACKGROUND) > 30 {
                drawn += 1;
            }
            for (i, n) in per_scan.iter_mut().enumerate() {
                if distance(p, viewer::scan_color(i)) <= 24 {
                    *n += 1;
                }
            }
        }
    }
    (drawn, per_scan)
}

#[test]
fn viewer_draws_the_scans_in_headless_chromium() {
    let Some(browser) = chromium() else {
        let why = "no chromium found (neither `chromium` nor `chromium-browser` on PATH, nor \
                   MTPCR_CHROMIUM): view.html was NOT tested in a browser";
        assert!(
            !in_ci(),
            "viewer_browser: {why}. In CI (CI=true) this is a failure: install Chromium \
             (Debian: apt-get install -y chromium; .ci/run does this)."
        );
        // Written to stderr directly: `eprintln!` would be captured (hidden) for a passing
        // test, and this skip must be seen.
        let _ = writeln!(
            std::io::stderr(),
            "\nSKIPPED viewer_browser: {why} (apt-get install chromium); \
             set CI=true to make this a failure\n"
        );
        return;
    };

    // Two spheres: side by side before, (nearly) on top of each other after.
    let before = [
        sphere(6000, [-0.6, 0.0, 0.0], 0.5),
        sphere(5000, [0.6, 0.1, 0.0], 0.5),
    ];
    let after = [
        sphere(6000, [0.0; 3], 0.5),
        sphere(5000, [0.01, 0.0, 0.0], 0.5),
    ];
    let b: Vec<&[[f64; 3]]> = before.iter().map(Vec::as_slice).collect();
    let a: Vec<&[[f64; 3]]> = after.iter().map(Vec::as_slice).collect();
    let labels = ["first <scan>.ply".to_string(), "second.ply".to_string()];
    let html = viewer::viewer_html(&b, &a, &labels, "m", "viewer test");

    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("view.html");
    std::fs::write(&page, html).unwrap();
    let area = (FREE[1] - FREE[0]) * (FREE[3] - FREE[2]);
    for (fragment, name) in [("", "after.png"), ("#before", "before.png")] {
        let png = dir.path().join(name);
        let pixels = screenshot(&browser, &page, fragment, &png, &dir.path().join("profile"));
        let (drawn, per_scan) = census(&pixels, 2);
        eprintln!("{name}: {drawn} of {area} pixels drawn, per scan colour {per_scan:?}");
        assert!(
            drawn > area / 20,
            "{name}: only {drawn} of {area} pixels differ from the background: WebGL drew \
             (almost) nothing"
        );
        assert!(
            per_scan.iter().all(|&n| n > 500),
            "{name}: pixels of each scan colour: {per_scan:?} (expected both scans visible)"
        );
    }
}
