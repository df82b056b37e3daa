//! The files the view serves, all in memory: the page and its vendor bundle are compiled into
//! the binary (a show has no network, so nothing comes from a CDN), the mannequin is built from
//! the rig at start, and `danced view` adds the dance and its song.

use std::collections::HashMap;
use std::sync::Arc;

use model::rig::Skeleton;

const INDEX_HTML: &[u8] = include_bytes!("../../web/index.html");
const APP_JS: &[u8] = include_bytes!("../../web/app.js");
/// three.js, GLTFLoader, OrbitControls and three-vrm (MIT, licence headers kept), bundled by
/// `daemon/web/vendor/build.sh` and stored gzipped.
const VENDOR_JS_GZ: &[u8] = include_bytes!("../../web/vendor.min.js.gz");

/// One file to serve.
#[derive(Clone, Debug)]
pub struct Asset {
    /// Its `Content-Type`.
    pub content_type: &'static str,
    /// Whether the body is gzip-encoded (sent with `Content-Encoding: gzip`).
    pub gzip: bool,
    /// The bytes.
    pub body: Arc<[u8]>,
}

/// Every file of the view by path.
#[derive(Clone, Debug, Default)]
pub struct Assets {
    files: HashMap<&'static str, Asset>,
}

impl Assets {
    /// The page, its scripts and the mannequin built on `skeleton`.
    pub fn page(skeleton: &Skeleton) -> Self {
        let mut a = Self::default();
        a.insert("/", "text/html; charset=utf-8", false, INDEX_HTML.into());
        a.insert(
            "/app.js",
            "text/javascript; charset=utf-8",
            false,
            APP_JS.into(),
        );
        a.insert(
            "/vendor.js",
            "text/javascript; charset=utf-8",
            true,
            VENDOR_JS_GZ.into(),
        );
        a.insert(
            "/mannequin.vrm",
            "model/gltf-binary",
            false,
            super::mannequin::mannequin_vrm(skeleton).into(),
        );
        a
    }

    /// Adds (or replaces) a file.
    pub fn insert(
        &mut self,
        path: &'static str,
        content_type: &'static str,
        gzip: bool,
        body: Arc<[u8]>,
    ) {
        self.files.insert(
            path,
            Asset {
                content_type,
                gzip,
                body,
            },
        );
    }

    /// The file at `path` (`/index.html` is `/`).
    pub fn get(&self, path: &str) -> Option<&Asset> {
        let path = if path == "/index.html" { "/" } else { path };
        self.files.get(path)
    }

    /// Bytes of the vendor bundle as embedded (gzipped).
    pub fn vendor_bytes() -> usize {
        VENDOR_JS_GZ.len()
    }
}

/// The `Content-Type` of an audio file by its extension (browsers decode all of these).
pub fn audio_content_type(path: &std::path::Path) -> &'static str {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("wav") => "audio/wav",
        Some("mp3") => "audio/mpeg",
        Some("ogg") | Some("oga") => "audio/ogg",
        Some("flac") => "audio/flac",
        Some("m4a") | Some("mp4") | Some("aac") => "audio/mp4",
        _ => "application/octet-stream",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_and_its_scripts_are_embedded() {
        let a = Assets::page(&Skeleton::default_adult());
        let index = a.get("/index.html").unwrap();
        assert!(std::str::from_utf8(&index.body).unwrap().contains("app.js"));
        let vendor = a.get("/vendor.js").unwrap();
        assert!(vendor.gzip);
        assert_eq!(&vendor.body[..2], &[0x1f, 0x8b], "gzip magic");
        assert_eq!(&a.get("/mannequin.vrm").unwrap().body[..4], b"glTF");
        assert!(a.get("/nope").is_none());
    }
}
