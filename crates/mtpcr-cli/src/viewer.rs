//! `view.html`: one self-contained HTML page that shows the scans in 3-D, before and after
//! registration, with three.js (WebGL). No network access is needed: the library, the page's
//! script and the points are all inside the page, so it opens from a `file://` URL.
//!
//! The WebGL library is three.js r111 (MIT licence), vendored in `assets/` from Debian's
//! package `libjs-three` 111+dfsg1-3 (bookworm): `assets/three-r111.min.js` is the package's
//! `/usr/share/javascript/three/three.min.js` and `assets/OrbitControls-r111.js` its
//! `examples/js/controls/OrbitControls.js` (the same release, a classic non-module script);
//! the package's copyright file, with the licence, is `assets/LICENSE-three.js.txt`.
//! r111 is the three.js that Debian ships; its WebGL 1 renderer and OrbitControls are all
//! this page uses.
//!
//! The points travel as base64 of little-endian `f32`, centred on the centroid of each
//! state (so `f32` keeps sub-micrometre detail on metre-sized scenes), subsampled with a
//! fixed (fractional) stride per scan to at most [`MAX_PER_SCAN`] points per scan and
//! [`BUDGET`] in all; the same points of a scan are shown before and after.
//!
//! This file uses nothing else of the CLI, so `tests/viewer_browser.rs` compiles it alone.

use std::fmt::Write as _;

/// Points shown per scan, at most.
pub const MAX_PER_SCAN: usize = 60_000;
/// Points shown in all (per state), at most.
pub const BUDGET: usize = 400_000;
/// Background of the 3-D view.
pub const BACKGROUND: [u8; 3] = [24, 27, 33];

/// One colour per scan, for every output (the page, `views.png`, `merged.ply`): red, green
/// and blue first, then the Okabe-Ito colour-blind-safe set and Paul Tol's muted and light
/// sets, all light enough for the dark background. Scans past the end reuse the colours
/// from the start.
pub const SCAN_COLORS: [[u8; 3]; 20] = [
    [214, 39, 40],
    [44, 160, 44],
    [31, 119, 180],
    [230, 159, 0],
    [86, 180, 233],
    [204, 121, 167],
    [240, 228, 66],
    [0, 158, 115],
    [213, 94, 0],
    [170, 68, 153],
    [221, 204, 119],
    [68, 170, 153],
    [204, 102, 119],
    [153, 153, 51],
    [136, 204, 238],
    [187, 187, 187],
    [255, 170, 187],
    [119, 170, 221],
    [238, 221, 136],
    [170, 170, 0],
];

static THREE_JS: &str = include_str!("../assets/three-r111.min.js");
static ORBIT_CONTROLS_JS: &str = include_str!("../assets/OrbitControls-r111.js");
static VIEWER_JS: &str = include_str!("viewer.js");

/// The colour of scan `i`.
pub fn scan_color(i: usize) -> [u8; 3] {
    SCAN_COLORS[i % SCAN_COLORS.len()]
}

/// Points shown of each scan: all of a scan up to [`MAX_PER_SCAN`], and no more than
/// [`BUDGET`] together. The budget is shared out evenly, a scan smaller than its share
/// leaving the rest to the others.
pub fn quotas(counts: &[usize]) -> Vec<usize> {
    let mut quota: Vec<usize> = counts.iter().map(|&n| n.min(MAX_PER_SCAN)).collect();
    if quota.iter().sum::<usize>() > BUDGET {
        let mut order: Vec<usize> = (0..counts.len()).collect();
        order.sort_by_key(|&i| quota[i]);
        let mut left = BUDGET;
        for (k, &i) in order.iter().enumerate() {
            let share = left / (order.len() - k);
            quota[i] = quota[i].min(share);
            left -= quota[i];
        }
    }
    quota
}

/// The indices of the `shown` points (of `n`) on show: evenly spaced with the stride
/// `n / shown` (rounded down to an index), from the first point. Deterministic.
pub fn picks(n: usize, shown: usize) -> impl Iterator<Item = usize> {
    let shown = shown.min(n);
    (0..shown).map(move |k| (k as u128 * n as u128 / shown as u128) as usize)
}

/// Escapes text for HTML element content and quoted attribute values.
pub fn escape_html(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// JSON that is safe inside a `<script>` element: `<`, `>` and `&` (which JSON has only
/// inside strings) become `\u003c`-style escapes, so no `</script>` or `<!--` can appear.
fn script_json(v: &serde_json::Value) -> String {
    v.to_string()
        .replace('<', "\\u003c")
        .replace('>', "\\u003e")
        .replace('&', "\\u0026")
}

/// Standard base64 (RFC 4648, with padding).
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(A[(n >> (18 - 6 * k)) as usize & 63] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Mean of all points of all scans (zero if there are none).
fn centroid(scans: &[&[[f64; 3]]]) -> [f64; 3] {
    let mut sum = [0.0; 3];
    let mut n = 0usize;
    for p in scans.iter().flat_map(|s| s.iter()) {
        for k in 0..3 {
            sum[k] += p[k];
        }
        n += 1;
    }
    if n == 0 {
        return [0.0; 3];
    }
    sum.map(|s| s / n as f64)
}

/// The [`picks`] of `shown` points, minus `center`, as base64 of little-endian `f32`
/// (x, y, z, x, ...).
fn encode(points: &[[f64; 3]], shown: usize, center: [f64; 3]) -> String {
    let mut bytes = Vec::with_capacity(shown * 12);
    for p in picks(points.len(), shown).map(|i| points[i]) {
        for k in 0..3 {
            bytes.extend_from_slice(&((p[k] - center[k]) as f32).to_le_bytes());
        }
    }
    base64(&bytes)
}

/// `12345` as `12,345`.
fn thousands(n: usize) -> String {
    let s = n.to_string();
    let mut out = String::new();
    for (i, c) in s.chars().enumerate() {
        if i > 0 && (s.len() - i) % 3 == 0 {
            out.push(',');
        }
        out.push(c);
    }
    out
}

fn css_rgb(c: [u8; 3]) -> String {
    format!("rgb({},{},{})", c[0], c[1], c[2])
}

/// A self-contained HTML page (no network access needed) showing the scans in 3-D.
/// `before[i]` and `after[i]` are the points of scan i in its own frame and in the common (registered) frame; `labels[i]` names scan i; `units` e.g. "m" or "" (unknown).
///
/// A scan without a label is called "scan N". Panics if `before` and `after` differ in the
/// number of scans or in the number of points of a scan.
pub fn viewer_html(
    before: &[&[[f64; 3]]],
    after: &[&[[f64; 3]]],
    labels: &[String],
    units: &str,
    title: &str,
) -> String {
    assert_eq!(
        before.len(),
        after.len(),
        "viewer_html: scans before and after"
    );
    for (i, (b, a)) in before.iter().zip(after).enumerate() {
        assert_eq!(b.len(), a.len(), "viewer_html: points of scan {}", i + 1);
    }
    let counts: Vec<usize> = before.iter().map(|s| s.len()).collect();
    let shown_counts = quotas(&counts);
    let (total, total_shown) = (
        counts.iter().sum::<usize>(),
        shown_counts.iter().sum::<usize>(),
    );
    let (center_before, center_after) = (centroid(before), centroid(after));
    let data = serde_json::json!({
        "units": units,
        "background": css_rgb(BACKGROUND),
        "colors": (0..counts.len()).map(scan_color).collect::<Vec<_>>(),
        "counts": counts,
        "shown": shown_counts,
        "center_before": center_before,
        "center_after": center_after,
        "before": before.iter().zip(&shown_counts).map(|(s, &k)| encode(s, k, center_before)).collect::<Vec<_>>(),
        "after": after.iter().zip(&shown_counts).map(|(s, &k)| encode(s, k, center_after)).collect::<Vec<_>>(),
    });

    let mut legend = String::new();
    for (i, (&n, &m)) in counts.iter().zip(&shown_counts).enumerate() {
        let label = labels
            .get(i)
            .cloned()
            .unwrap_or_else(|| format!("scan {}", i + 1));
        let key = if i < 10 {
            format!(" (key {})", (i + 1) % 10)
        } else {
            String::new()
        };
        let _ = writeln!(
            legend,
            "<label class=\"item\" title=\"{label}: click to hide or show{key}\"><input type=\"checkbox\" \
             data-scan=\"{i}\" checked><span class=\"swatch\" style=\"background:{color}\"></span>\
             <span class=\"name\">{label}</span><span class=\"n\">{shown} of {n}</span></label>",
            color = css_rgb(scan_color(i)),
            label = escape_html(&label),
            shown = thousands(m),
            n = thousands(n),
        );
    }
    let counts_text = if total_shown == total {
        format!("Showing all {} points.", thousands(total))
    } else {
        format!(
            "Showing {} of {} points (evenly spaced through each scan).",
            thousands(total_shown),
            thousands(total)
        )
    };
    let units_text = if units.is_empty() {
        "Coordinates in the data's units (not stated).".to_string()
    } else {
        format!("Coordinates in {}.", escape_html(units))
    };

    let title = escape_html(title);
    let mut page = String::with_capacity(THREE_JS.len() + 200_000 + total_shown * 32);
    let _ = write!(
        page,
        r#"<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{title}</title>
<style>
html, body {{ margin: 0; height: 100%; overflow: hidden; background: {bg}; color: #e8eaed;
  font: 14px/1.4 system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif; }}
#view {{ position: fixed; inset: 0; width: 100%; height: 100%; display: block; touch-action: none; }}
.box {{ position: fixed; background: rgba(16, 18, 22, 0.82); border: 1px solid #3c4048;
  border-radius: 6px; padding: 10px 12px; }}
#panel {{ top: 10px; left: 10px; max-width: 330px; }}
#panel h1 {{ font-size: 16px; margin: 0 0 6px; overflow-wrap: anywhere; }}
#panel .row {{ margin: 6px 0; }}
#state {{ font-weight: 600; }}
button {{ font: inherit; color: #e8eaed; background: #2d3139; border: 1px solid #5f6570;
  border-radius: 4px; padding: 4px 10px; cursor: pointer; }}
button:hover {{ background: #3a3f49; }}
input[type=range] {{ vertical-align: middle; width: 130px; }}
.note {{ color: #b0b4bb; font-size: 13px; }}
#legend {{ top: 10px; right: 10px; max-width: 400px; max-height: calc(100% - 90px); overflow-y: auto; }}
#legend .head {{ font-weight: 600; margin-bottom: 4px; }}
#legend .item {{ display: flex; align-items: center; gap: 7px; padding: 3px 2px; cursor: pointer;
  user-select: none; }}
#legend .item input {{ margin: 0; }}
#legend .swatch {{ width: 14px; height: 14px; border-radius: 50%; flex: none; }}
#legend .name {{ flex: 1; min-width: 0; white-space: nowrap; overflow: hidden; text-overflow: ellipsis; }}
#legend .n {{ color: #b0b4bb; font-size: 12px; white-space: nowrap; }}
#legend .item:has(input:not(:checked)) {{ opacity: 0.45; }}
#scale {{ bottom: 10px; left: 10px; }}
#bar {{ height: 6px; border: 2px solid #e8eaed; border-top: none; width: 120px; margin-bottom: 3px; }}
#help {{ bottom: 10px; right: 10px; color: #b0b4bb; font-size: 12px; max-width: 520px; }}
body.bare .box:not(#error) {{ display: none; }}
#error {{ display: none; top: 40%; left: 50%; transform: translateX(-50%); color: #ffb4a9; }}
</style>
</head>
<body data-state="after">
<canvas id="view"></canvas>
<div id="panel" class="box">
<h1>{title}</h1>
<div id="state" class="row">After registration: all scans in the common frame</div>
<div class="row"><button id="toggle" type="button">Show before (B)</button> <button id="reset" type="button">Reset view (R)</button></div>
<div class="row"><label>Point size <input id="size" type="range" min="1" max="8" step="0.5" value="2"> <span id="size-value">2</span> px</label></div>
<div id="counts" class="row note">{counts_text}</div>
<div id="extent" class="note"></div>
<div id="units" class="note">{units_text}</div>
</div>
<div id="legend" class="box">
<div class="head">Scans (click to hide/show)</div>
{legend}</div>
<div id="scale" class="box"><div id="bar"></div><span id="bar-label"></span></div>
<div id="help" class="box">Drag: rotate &middot; right-drag or shift-drag: pan &middot; wheel or pinch: zoom &middot; B: before/after &middot; R: reset view &middot; 1&ndash;9, 0: hide/show a scan &middot; H: hide/show these boxes</div>
<div id="error" class="box"></div>
<script type="application/json" id="mtpcr-data">{data}</script>
<script>
{three}
</script>
<script>
{orbit}
</script>
<script>
{viewer}
</script>
</body>
</html>
"#,
        bg = css_rgb(BACKGROUND),
        data = script_json(&data),
        three = THREE_JS,
        orbit = ORBIT_CONTROLS_JS,
        viewer = VIEWER_JS,
    );
    page
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode_base64(s: &str) -> Vec<u8> {
        let value = |c: u8| -> u32 {
            match c {
                b'A'..=b'Z' => u32::from(c - b'A'),
                b'a'..=b'z' => u32::from(c - b'a') + 26,
                b'0'..=b'9' => u32::from(c - b'0') + 52,
                b'+' => 62,
                b'/' => 63,
                _ => panic!("not base64: {c}"),
            }
        };
        assert_eq!(s.len() % 4, 0);
        let mut out = Vec::new();
        for chunk in s.as_bytes().chunks(4) {
            let pad = chunk.iter().filter(|&&c| c == b'=').count();
            let n = chunk[..4 - pad]
                .iter()
                .enumerate()
                .fold(0u32, |n, (k, &c)| n | (value(c) << (18 - 6 * k)));
            out.extend_from_slice(&n.to_be_bytes()[1..4 - pad]);
        }
        out
    }

    /// The JSON data block of a page.
    fn page_data(page: &str) -> serde_json::Value {
        let start = page.find(r#"id="mtpcr-data">"#).unwrap() + r#"id="mtpcr-data">"#.len();
        let end = start + page[start..].find("</script>").unwrap();
        serde_json::from_str(&page[start..end]).unwrap()
    }

    fn decode_points(b64: &str) -> Vec<[f32; 3]> {
        let bytes = decode_base64(b64);
        assert_eq!(bytes.len() % 12, 0);
        bytes
            .chunks(12)
            .map(|c| {
                std::array::from_fn(|k| f32::from_le_bytes(c[4 * k..4 * k + 4].try_into().unwrap()))
            })
            .collect()
    }

    /// A wavy sheet of `n` points around `offset`.
    fn cloud(n: usize, offset: [f64; 3]) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let (u, v) = ((i % 200) as f64 / 200.0, (i / 200) as f64 / 200.0);
                [
                    offset[0] + u,
                    offset[1] + v,
                    offset[2] + 0.1 * (6.0 * u).sin() * v,
                ]
            })
            .collect()
    }

    #[test]
    fn base64_round_trips_every_length() {
        for n in 0..20 {
            let bytes: Vec<u8> = (0..n).map(|i| (i * 37 + 11) as u8).collect();
            assert_eq!(decode_base64(&base64(&bytes)), bytes, "length {n}");
        }
        assert_eq!(base64(b"Man"), "TWFu");
        assert_eq!(base64(b"Ma"), "TWE=");
        assert_eq!(base64(b"M"), "TQ==");
    }

    #[test]
    fn quotas_keep_small_scans_whole_and_share_the_budget() {
        assert_eq!(quotas(&[1000, 0, 60_000]), vec![1000, 0, 60_000]);
        assert_eq!(quotas(&[120_000]), vec![MAX_PER_SCAN]);
        assert_eq!(quotas(&[100_000; 20]), vec![20_000; 20]);
        // A small scan leaves its share to the large ones.
        let q = quotas(&[
            5_000, 1_000_000, 1_000_000, 1_000_000, 1_000_000, 1_000_000, 1_000_000, 1_000_000,
        ]);
        assert_eq!(q[0], 5_000);
        assert_eq!(q.iter().sum::<usize>(), BUDGET);
        assert!(q.iter().all(|&n| n <= MAX_PER_SCAN));
    }

    #[test]
    fn picks_are_evenly_spaced_and_start_at_the_first_point() {
        assert_eq!(picks(10, 4).collect::<Vec<_>>(), vec![0, 2, 5, 7]);
        assert_eq!(picks(5, 5).collect::<Vec<_>>(), vec![0, 1, 2, 3, 4]);
        assert_eq!(picks(3, 9).collect::<Vec<_>>(), vec![0, 1, 2]);
        assert_eq!(picks(0, 0).count(), 0);
    }

    #[test]
    fn page_decodes_back_to_the_points_with_their_counts() {
        let before: Vec<Vec<[f64; 3]>> = (0..3)
            .map(|i| cloud(1000 + 500 * i, [1000.0 + i as f64, -50.0, 3.0]))
            .collect();
        let after: Vec<Vec<[f64; 3]>> = (0..3)
            .map(|i| cloud(1000 + 500 * i, [0.01 * i as f64, 0.0, 0.0]))
            .collect();
        fn refs(v: &[Vec<[f64; 3]>]) -> Vec<&[[f64; 3]]> {
            v.iter().map(Vec::as_slice).collect()
        }
        let labels: Vec<String> = (1..=3).map(|i| format!("cloud {i}")).collect();
        let page = viewer_html(&refs(&before), &refs(&after), &labels, "m", "Test");
        let data = page_data(&page);
        assert_eq!(data["counts"], serde_json::json!([1000, 1500, 2000]));
        assert_eq!(data["shown"], data["counts"]);
        assert!(page.contains("Showing all 4,500 points."));
        assert!(page.contains("<span class=\"n\">1,500 of 1,500</span>"));
        assert!(page.contains("Coordinates in m."));
        for (state, scans) in [("before", &before), ("after", &after)] {
            let center: Vec<f64> =
                serde_json::from_value(data[format!("center_{state}")].clone()).unwrap();
            for (i, scan) in scans.iter().enumerate() {
                let got = decode_points(data[state][i].as_str().unwrap());
                assert_eq!(got.len(), scan.len(), "{state} {i}");
                for (g, p) in got.iter().zip(scan.iter()) {
                    for k in 0..3 {
                        let back = f64::from(g[k]) + center[k];
                        assert!(
                            (back - p[k]).abs() < 1e-5,
                            "{state} {i}: {back} vs {}",
                            p[k]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn large_scans_are_subsampled_and_the_page_says_so() {
        let big = cloud(150_000, [0.0; 3]);
        let small = cloud(7_000, [0.0; 3]);
        let scans = [big.as_slice(), small.as_slice()];
        let page = viewer_html(&scans, &scans, &[], "", "t");
        let data = page_data(&page);
        assert_eq!(data["shown"], serde_json::json!([60_000, 7_000]));
        assert!(
            page.contains("Showing 67,000 of 157,000 points"),
            "counts note"
        );
        assert!(page.contains("<span class=\"name\">scan 1</span>"));
        assert!(page.contains("<span class=\"n\">60,000 of 150,000</span>"));
        assert!(page.contains("(not stated)"));
        let got = decode_points(data["after"][0].as_str().unwrap());
        let c: Vec<f64> = serde_json::from_value(data["center_after"].clone()).unwrap();
        for (j, g) in got.iter().enumerate() {
            let p = big[j * 5 / 2];
            assert!(
                (0..3).all(|k| (f64::from(g[k]) + c[k] - p[k]).abs() < 1e-5),
                "point {j}"
            );
        }
    }

    #[test]
    fn labels_and_title_are_escaped() {
        let nasty = r#"a<b> "q" 'x' </script><script>alert(1)</script> & co.ply"#;
        let labels = vec![nasty.to_string(), "plain.ply".to_string()];
        let a = cloud(10, [0.0; 3]);
        let scans = [a.as_slice(), a.as_slice()];
        let page = viewer_html(&scans, &scans, &labels, "<m>", nasty);
        let escaped = "a&lt;b&gt; &quot;q&quot; &#39;x&#39; &lt;/script&gt;&lt;script&gt;alert(1)&lt;/script&gt; &amp; co.ply";
        assert!(page.contains(&format!("<span class=\"name\">{escaped}</span>")));
        assert!(page.contains("<span class=\"name\">plain.ply</span>"));
        assert!(page.contains(&format!("<title>{escaped}</title>")));
        assert!(page.contains("Coordinates in &lt;m&gt;."));
        assert!(!page.contains("alert(1)</script>"));
        assert!(!page.contains("<m>"));
        // Exactly our four script elements.
        assert_eq!(page.matches("<script").count(), 4);
        assert_eq!(page.matches("</script>").count(), 4);
        // The units reach the script intact through the JSON block.
        assert_eq!(page_data(&page)["units"], "<m>");
    }

    #[test]
    fn page_loads_nothing_from_the_network() {
        let a = cloud(10, [0.0; 3]);
        let scans = [a.as_slice()];
        let page = viewer_html(&scans, &scans, &[], "", "t").to_ascii_lowercase();
        for attr in ["src", "href", "url(", "import", "@import"] {
            for quote in ["", "\"", "'"] {
                for scheme in ["http://", "https://", "//"] {
                    let needle = if attr.ends_with('(') || attr.contains("import") {
                        format!("{attr}{quote}{scheme}")
                    } else {
                        format!("{attr}={quote}{scheme}")
                    };
                    assert!(!page.contains(&needle), "{needle}");
                }
            }
        }
        assert!(!page.contains("<link"));
        assert!(!page.contains("<iframe"));
        assert!(!page.contains("<script src"));
    }

    #[test]
    fn three_scans_of_40k_points_stay_under_10_mb() {
        let clouds: Vec<Vec<[f64; 3]>> = (0..3)
            .map(|i| cloud(40_000, [i as f64, 0.0, 0.0]))
            .collect();
        let scans: Vec<&[[f64; 3]]> = clouds.iter().map(Vec::as_slice).collect();
        let page = viewer_html(&scans, &scans, &[], "m", "t");
        assert!(page.len() < 10_000_000, "{} bytes", page.len());
        assert_eq!(
            page_data(&page)["shown"],
            serde_json::json!([40_000, 40_000, 40_000])
        );
    }

    #[test]
    fn twenty_scans_get_twenty_colours() {
        let colors: std::collections::HashSet<[u8; 3]> = (0..20).map(scan_color).collect();
        assert_eq!(colors.len(), 20);
        assert!(!colors.contains(&BACKGROUND));
    }
}
