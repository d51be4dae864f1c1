//! The mesh preview (PNG) and the HTML run report, rendered.

use super::*;

/// The preview's pixels: (width, height, RGB bytes).
fn decode_png(path: &Path) -> (usize, usize, Vec<u8>) {
    let d = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut r = d.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size()];
    let info = r.next_frame(&mut buf).unwrap();
    let ch = info.color_type.samples();
    let px: Vec<u8> = buf[..info.buffer_size()]
        .chunks(ch)
        .flat_map(|c| [c[0], c[1], c[2]])
        .collect();
    (info.width as usize, info.height as usize, px)
}

/// `--preview` draws the torus: its front silhouette has the area of the torus's projection
/// (a 2R × 2r band with round ends), and no face seen from behind shows (it is closed and
/// outward). `--report` writes JSON with the stages and the check, and an HTML page that
/// headless Chromium renders (where it is installed) with the picture in it.
#[test]
fn the_preview_shows_the_shape_and_the_report_renders() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pts = torus(d);
    let (png, html, json) = (d.join("t.png"), d.join("t.html"), d.join("t.json"));
    recon(
        &pts,
        &d.join("m.ply"),
        &["--preview", s(&png), "--report", s(&html)],
    );
    recon(&pts, &d.join("n.ply"), &["--report", s(&json)]);
    let (w, h, px) = decode_png(&png);
    assert_eq!((w, h), (1200, 400));
    let at = |x: usize, y: usize| -> [u8; 3] {
        let i = 3 * (y * w + x);
        [px[i], px[i + 1], px[i + 2]]
    };
    let front = (0..h)
        .flat_map(|y| (0..h).map(move |x| (x, y)))
        .filter(|&(x, y)| at(x, y) != [255, 255, 255])
        .count() as f64;
    // The torus's bounds: 2.7 × 2.7 × 0.7; 92% of 400 pixels over their diagonal.
    let scale = 0.92 * 400.0 / (2.7f64 * 2.7 * 2.0 + 0.49).sqrt();
    let (r_major, r_minor) = (1.0, 0.35);
    let area = 4.0 * r_major * r_minor + std::f64::consts::PI * r_minor * r_minor;
    let want = area * scale * scale;
    assert!(
        (front / want - 1.0).abs() < 0.03,
        "front view: {front} px, expected {want}"
    );
    // Back faces are tinted blue (more blue than red): none on a closed outward surface.
    let back = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let c = at(x, y);
            c[2] as i32 > c[0] as i32 + 40
        })
        .count();
    assert_eq!(back, 0, "faces seen from behind in the picture");

    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(j["command"], "reconstruct");
    assert_eq!(j["points"], 30000);
    let stages: Vec<&str> = j["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["name"].as_str().unwrap())
        .collect();
    assert!(
        stages.contains(&"leaves") && stages.contains(&"tiles"),
        "{stages:?}"
    );
    assert_eq!(j["check"]["watertight"], true);
    assert_eq!(j["check"]["triangles"], j["result"]["faces"]);
    assert!(j["memory"].as_array().unwrap().len() >= 2);
    assert!(j["leaf_map"]["n"].as_u64().unwrap() > 0);

    let page = std::fs::read_to_string(&html).unwrap();
    assert!(page.contains("data:image/png;base64,") && !page.contains("<script"));
    let chromium = ["chromium", "chromium-browser"].into_iter().find(|c| {
        Command::new(c)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
    });
    let Some(chromium) = chromium else {
        eprintln!("skipped the browser check: no chromium installed");
        return;
    };
    let shot = d.join("shot.png");
    let profile = d.join("profile");
    let o = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--enable-logging=stderr",
            "--window-size=1300,1400",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--screenshot={}", shot.display()))
        .arg(format!("file://{}", html.display()))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.success() && shot.exists(),
        "chromium failed: {err}"
    );
    let console: Vec<&str> = err.lines().filter(|l| l.contains("CONSOLE")).collect();
    assert!(
        console.is_empty(),
        "console messages from the report: {console:?}"
    );
    // The page shows the picture: many pixels of the surface's grey (not white, not text).
    let (sw, sh, spx) = decode_png(&shot);
    assert!(sw >= 1000 && sh >= 1000);
    let grey = spx
        .chunks(3)
        .filter(|c| {
            c[0] > 120 && c[0] < 230 && c[0].abs_diff(c[1]) < 12 && c[0].abs_diff(c[2]) < 20
        })
        .count();
    assert!(grey > 10_000, "the screenshot shows {grey} surface pixels");
}
