//! Proves the CDP helper in `browser/` works: headless Chromium loads a page from a loopback
//! server, runs WebGL2 on SwiftShader, cannot reach the internet, and takes a screenshot.

mod browser;

use std::io::{Read, Write};
use std::net::TcpListener;
use std::time::{Duration, Instant};

const PAGE: &str = r#"<!doctype html>
<html><body style="margin:0; background:#000">
<canvas id="c" width="320" height="240"></canvas>
<script>
const gl = document.getElementById("c").getContext("webgl2");
let pixel = null;
if (gl) {
  gl.clearColor(1.0, 0.5, 0.0, 1.0);
  gl.clear(gl.COLOR_BUFFER_BIT);
  const p = new Uint8Array(4);
  gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, p);
  pixel = Array.from(p);
}
const debug = gl && gl.getExtension("WEBGL_debug_renderer_info");
window.glInfo = {
  webgl2: !!gl,
  renderer: gl ? gl.getParameter(gl.RENDERER) : null,
  unmasked: debug ? gl.getParameter(debug.UNMASKED_RENDERER_WEBGL) : null,
  pixel,
};
console.log("hello");
fetch("http://example.com/").then(() => { window.fetchFailed = false; },
                                  () => { window.fetchFailed = true; });
</script>
</body></html>"#;

/// Serves `PAGE` for any path, forever, on a fresh loopback port; returns its URL.
fn serve() -> String {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}/", listener.local_addr().unwrap());
    std::thread::spawn(move || {
        for mut stream in listener.incoming().flatten() {
            let mut request = Vec::new();
            let mut buf = [0; 1024];
            while !request.windows(4).any(|w| w == b"\r\n\r\n") {
                match stream.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => request.extend_from_slice(&buf[..n]),
                }
            }
            let head = format!(
                "HTTP/1.1 200 OK\r\nContent-Type: text/html\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
                PAGE.len()
            );
            let _ = stream
                .write_all(head.as_bytes())
                .and_then(|()| stream.write_all(PAGE.as_bytes()));
        }
    });
    url
}

#[test]
fn browser_runs_webgl2_offline_and_screenshots() {
    if !browser::require_chromium() {
        return;
    }
    let url = serve();
    let start = Instant::now();
    let browser = browser::Browser::launch(640, 480).unwrap();
    let launched = start.elapsed();
    let page = browser.open(&url).unwrap();
    eprintln!("launch {launched:?}, launch + open {:?}", start.elapsed());

    let gl = page
        .wait_for("window.glInfo", Duration::from_secs(10))
        .unwrap();
    eprintln!("WebGL: {gl}");
    assert_eq!(gl["webgl2"], true, "no WebGL2: {gl}");
    assert_eq!(
        gl["pixel"],
        serde_json::json!([255, 128, 0, 255]),
        "clear colour not read back"
    );
    let failed = page
        .wait_for("window.fetchFailed", Duration::from_secs(10))
        .unwrap();
    assert_eq!(failed, true);

    let console = page.console();
    assert!(
        console.iter().any(|line| line == "log: hello"),
        "console: {console:?}"
    );
    let thrown = page.eval("null.x").unwrap_err();
    assert!(thrown.contains("TypeError"), "{thrown}");
    let late = page.wait_for("window.never", Duration::from_millis(200));
    let late = late.unwrap_err();
    assert!(late.contains("log: hello"), "no console in: {late}");
    let requests = page.requests();
    eprintln!("requests: {requests:?}");
    assert!(requests.contains(&url), "requests: {requests:?}");

    let png = page.screenshot_png().unwrap();
    assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"), "not a PNG");
    assert!(
        (1_000..10_000_000).contains(&png.len()),
        "PNG of {} bytes",
        png.len()
    );
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../target/browser-smoke.png");
    std::fs::write(path, &png).unwrap();
    eprintln!(
        "renderer {}, screenshot {} bytes in {path}",
        gl["renderer"],
        png.len()
    );
    eprintln!("total {:?}", start.elapsed());
}
