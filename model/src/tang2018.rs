//! Reader for the tang2018 dance data set ("Dance with Melody", Tang, Jia & Mao 2018).
//!
//! One folder per dance, `DANCE_<style>_<n>/`: `skeletons.npy` (float32 `[frames, 23, 3]`, cm,
//! relative to the frame's centre, Y up) and `center.npy` (float32 `[frames, 3]`, cm), or the
//! upstream `skeletons.json` (`{"length", "center", "skeletons"}`) holding the same numbers;
//! `config.json` (`{"start_position", "end_position"}` in 25 fps music frames) and, for most
//! dances, `audio.mp3`. Positions are returned as read (centimetres); fitting the rig is the
//! importer's job.

use std::fs;
use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::ModelError;

/// Points per frame in the data set.
pub const TANG_POINTS: usize = 23;
/// Motion frames per second.
pub const TANG_FPS: f64 = 25.0;

/// The style letter of a dance's folder name (`DANCE_W_3` → `W`: cha-cha C, rumba R, tango T,
/// waltz W).
pub fn style_letter(dance: &str) -> Option<char> {
    dance.strip_prefix("DANCE_")?.chars().next()
}

/// One dance as stored: noisy points, the body's centre, the danced span, the song.
#[derive(Clone, Debug)]
pub struct TangDance {
    /// Folder name, e.g. `DANCE_W_1`.
    pub name: String,
    /// Style letter: C (cha-cha), R (rumba), T (tango), W (waltz).
    pub style: char,
    /// Per frame, the 23 points relative to the centre, in cm.
    pub points: Vec<[Vec3; TANG_POINTS]>,
    /// Per frame, the centre (global body position), in cm.
    pub center: Vec<Vec3>,
    /// `start_position`, `end_position` in 25 fps music frames (approximate upstream).
    pub music_span: Option<(f64, f64)>,
    /// The song, when the data set has it.
    pub audio: Option<PathBuf>,
}

impl TangDance {
    /// Number of motion frames.
    pub fn frames(&self) -> usize {
        self.points.len()
    }

    /// Length in seconds.
    pub fn seconds(&self) -> f64 {
        self.frames() as f64 / TANG_FPS
    }
}

fn malformed(path: &Path, reason: impl Into<String>) -> ModelError {
    ModelError::DataSetMalformed {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

fn read_npy(path: &Path) -> Result<ndarray::ArrayD<f32>, ModelError> {
    let file = fs::File::open(path).map_err(|source| ModelError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    ndarray::ArrayD::<f32>::read_npy(file)
        .map_err(|e| malformed(path, format!("not a float32 .npy array: {e}")))
}

use ndarray_npy::ReadNpyExt;

fn finite(v: Vec3, path: &Path) -> Result<Vec3, ModelError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(malformed(path, "contains NaN or infinite coordinates"))
    }
}

fn from_npy(dir: &Path) -> Result<(Vec<[Vec3; TANG_POINTS]>, Vec<Vec3>), ModelError> {
    let sp = dir.join("skeletons.npy");
    let cp = dir.join("center.npy");
    let s = read_npy(&sp)?;
    let c = read_npy(&cp)?;
    if s.ndim() != 3 || s.shape()[1] != TANG_POINTS || s.shape()[2] != 3 {
        return Err(malformed(
            &sp,
            format!("shape {:?}, expected [frames, 23, 3]", s.shape()),
        ));
    }
    if c.ndim() != 2 || c.shape()[1] != 3 {
        return Err(malformed(
            &cp,
            format!("shape {:?}, expected [frames, 3]", c.shape()),
        ));
    }
    if s.shape()[0] != c.shape()[0] {
        return Err(malformed(
            &cp,
            format!(
                "{} frames, skeletons.npy has {}",
                c.shape()[0],
                s.shape()[0]
            ),
        ));
    }
    let s = s.as_standard_layout();
    let c = c.as_standard_layout();
    let (sv, cv) = (
        s.as_slice().unwrap_or_default(),
        c.as_slice().unwrap_or_default(),
    );
    let mut points = Vec::with_capacity(s.shape()[0]);
    for f in sv.chunks_exact(TANG_POINTS * 3) {
        let mut frame = [Vec3::ZERO; TANG_POINTS];
        for (p, xyz) in frame.iter_mut().zip(f.chunks_exact(3)) {
            *p = finite(Vec3::new(xyz[0], xyz[1], xyz[2]), &sp)?;
        }
        points.push(frame);
    }
    let center = cv
        .chunks_exact(3)
        .map(|x| finite(Vec3::new(x[0], x[1], x[2]), &cp))
        .collect::<Result<_, _>>()?;
    Ok((points, center))
}

fn vec3(v: &serde_json::Value, path: &Path) -> Result<Vec3, ModelError> {
    let a = v
        .as_array()
        .filter(|a| a.len() == 3)
        .ok_or_else(|| malformed(path, "expected [x, y, z]"))?;
    let f = |i: usize| {
        a[i].as_f64()
            .map(|x| x as f32)
            .ok_or_else(|| malformed(path, "coordinate is not a number"))
    };
    finite(Vec3::new(f(0)?, f(1)?, f(2)?), path)
}

fn read_json(path: &Path) -> Result<serde_json::Value, ModelError> {
    let text = fs::read_to_string(path).map_err(|source| ModelError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|e| malformed(path, format!("invalid JSON: {e}")))
}

fn from_json(path: &Path) -> Result<(Vec<[Vec3; TANG_POINTS]>, Vec<Vec3>), ModelError> {
    let v = read_json(path)?;
    let skel = v
        .get("skeletons")
        .and_then(|s| s.as_array())
        .ok_or_else(|| malformed(path, "no \"skeletons\" array"))?;
    let cent = v
        .get("center")
        .and_then(|s| s.as_array())
        .ok_or_else(|| malformed(path, "no \"center\" array"))?;
    if skel.len() != cent.len() {
        return Err(malformed(
            path,
            format!(
                "{} skeleton frames but {} centre frames",
                skel.len(),
                cent.len()
            ),
        ));
    }
    let mut points = Vec::with_capacity(skel.len());
    for (i, f) in skel.iter().enumerate() {
        let pts = f
            .as_array()
            .filter(|a| a.len() == TANG_POINTS)
            .ok_or_else(|| malformed(path, format!("frame {i}: expected 23 points")))?;
        let mut frame = [Vec3::ZERO; TANG_POINTS];
        for (p, v) in frame.iter_mut().zip(pts) {
            *p = vec3(v, path)?;
        }
        points.push(frame);
    }
    let center = cent
        .iter()
        .map(|c| vec3(c, path))
        .collect::<Result<_, _>>()?;
    Ok((points, center))
}

fn read_span(path: &Path) -> Result<Option<(f64, f64)>, ModelError> {
    if !path.exists() {
        return Ok(None);
    }
    let v = read_json(path)?;
    let get = |k: &str| {
        v.get(k)
            .and_then(|x| x.as_f64())
            .ok_or_else(|| malformed(path, format!("no number \"{k}\"")))
    };
    Ok(Some((get("start_position")?, get("end_position")?)))
}

/// Reads one dance folder (either layout). A dance without `audio.mp3` is still returned, as
/// motion only.
pub fn load_dance(dir: &Path) -> Result<TangDance, ModelError> {
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let style = name
        .strip_prefix("DANCE_")
        .and_then(|s| s.chars().next())
        .unwrap_or('?');
    let (points, center) = if dir.join("skeletons.npy").exists() {
        from_npy(dir)?
    } else if dir.join("skeletons.json").exists() {
        from_json(&dir.join("skeletons.json"))?
    } else {
        return Err(ModelError::DataSetNoMotion(dir.to_path_buf()));
    };
    if points.is_empty() {
        return Err(malformed(dir, "no frames"));
    }
    let audio = Some(dir.join("audio.mp3")).filter(|p| p.is_file());
    Ok(TangDance {
        name,
        style,
        points,
        center,
        music_span: read_span(&dir.join("config.json"))?,
        audio,
    })
}

/// Folders under `root` that look like dances (`DANCE_*`), sorted by name.
pub fn dance_dirs(root: &Path) -> Result<Vec<PathBuf>, ModelError> {
    let rd = fs::read_dir(root).map_err(|source| ModelError::Io {
        path: root.to_path_buf(),
        source,
    })?;
    let mut v: Vec<PathBuf> = rd
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.is_dir()
                && p.file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with("DANCE_"))
        })
        .collect();
    v.sort();
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("danced-tang-{name}-{}", std::process::id()));
        fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn json_layout_reads_like_the_npy_layout() {
        let dir = scratch("DANCE_W_0");
        let mut frames = Vec::new();
        for f in 0..3 {
            let pts: Vec<String> = (0..TANG_POINTS)
                .map(|j| format!("[{}, {}, {}]", j, f, -(j as f32) / 2.0))
                .collect();
            frames.push(format!("[{}]", pts.join(",")));
        }
        let json = format!(
            "{{\"length\": 3, \"center\": [[1,2,3],[4,5,6],[7,8,9]], \"skeletons\": [{}]}}",
            frames.join(",")
        );
        fs::write(dir.join("skeletons.json"), json).unwrap();
        fs::write(
            dir.join("config.json"),
            "{\"start_position\": 10, \"end_position\": 12}",
        )
        .unwrap();
        let d = load_dance(&dir).unwrap();
        assert_eq!(d.frames(), 3);
        assert_eq!(d.points[2][5], Vec3::new(5.0, 2.0, -2.5));
        assert_eq!(d.center[1], Vec3::new(4.0, 5.0, 6.0));
        assert_eq!(d.music_span, Some((10.0, 12.0)));
        assert!(d.audio.is_none());
        fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn malformed_files_name_themselves() {
        let dir = scratch("DANCE_C_0");
        fs::write(
            dir.join("skeletons.json"),
            "{\"center\": [], \"skeletons\": [[1,2]]}",
        )
        .unwrap();
        let e = load_dance(&dir).unwrap_err().to_string();
        assert!(e.contains("skeletons.json"), "{e}");
        fs::write(dir.join("skeletons.npy"), b"not numpy").unwrap();
        fs::write(dir.join("center.npy"), b"not numpy").unwrap();
        let e = load_dance(&dir).unwrap_err().to_string();
        assert!(e.contains("skeletons.npy"), "{e}");
        let empty = scratch("DANCE_T_0");
        assert!(matches!(
            load_dance(&empty),
            Err(ModelError::DataSetNoMotion(_))
        ));
        fs::remove_dir_all(&dir).ok();
        fs::remove_dir_all(&empty).ok();
    }

    #[test]
    fn shared_data_set_loads_when_present() {
        let Some(data) = testkit::require_shared("tang2018") else {
            return;
        };
        let root = data.join("tang2018");
        let dirs = dance_dirs(&root).unwrap();
        assert_eq!(dirs.len(), 43);
        let mut minutes = 0.0;
        let mut with_audio = 0;
        for d in &dirs {
            let dance = load_dance(d).unwrap();
            assert_eq!(dance.center.len(), dance.frames());
            minutes += dance.seconds() / 60.0;
            with_audio += dance.audio.is_some() as usize;
        }
        assert_eq!(with_audio, 38);
        assert!((minutes - 46.0).abs() < 2.0, "{minutes} minutes of motion");
    }
}
