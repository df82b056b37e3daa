//! Named key poses the performer can call (MIDI notes, OSC `/keypose`): a BVH file on any rig
//! plus a TOML file naming its frames.
//!
//! ```toml
//! bvh = "bank.bvh"            # relative to this file; any rig our BVH retargeting maps
//! [[pose]]
//! name = "pose-1"
//! frame = 0
//! description = "both arms up"   # optional, shown by `danced poses`
//! ```
//! The shipped bank (`configs/poses/bank.toml`) holds 16 poses picked from the shipped clip
//! library as far from each other as possible, so a controller's pads give visibly different
//! shapes; `danced library poses` rebuilds it.

use std::path::{Path, PathBuf};

use glam::{Quat, Vec3};
use model::bvh::{Bvh, RetargetOptions, import};
use model::retrieval::ClipLibrary;
use model::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use serde::Deserialize;
use thiserror::Error;

/// The shipped bank's TOML.
pub const SHIPPED_BANK_TOML: &str = include_str!("../../configs/poses/bank.toml");
/// The shipped bank's BVH.
pub const SHIPPED_BANK_BVH: &str = include_str!("../../configs/poses/bank.bvh");

/// Why a pose bank could not be loaded.
#[derive(Debug, Error)]
pub enum PoseBankError {
    /// A file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        source: std::io::Error,
    },
    /// The TOML is malformed or has unknown keys.
    #[error("{path}: {message}")]
    Toml {
        /// The file.
        path: PathBuf,
        /// The parser's message (names the key and line).
        message: String,
    },
    /// The BVH could not be read or put on the rig.
    #[error("{path}: {message}")]
    Bvh {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// A pose entry is wrong (frame out of range, duplicate name).
    #[error("{path}: pose {name:?}: {message}")]
    Pose {
        /// The TOML file.
        path: PathBuf,
        /// The pose.
        name: String,
        /// What is wrong.
        message: String,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BankFile {
    bvh: String,
    #[serde(default)]
    pose: Vec<PoseEntry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PoseEntry {
    name: String,
    frame: usize,
    #[serde(default)]
    description: String,
}

/// One named pose.
#[derive(Clone, Debug, PartialEq)]
pub struct NamedPose {
    /// What the performer calls it.
    pub name: String,
    /// What it looks like.
    pub description: String,
    /// Local rotation of every joint (root translation is not part of a key pose).
    pub rotations: [Quat; JOINT_COUNT],
}

/// Named key poses.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PoseBank {
    poses: Vec<NamedPose>,
}

impl PoseBank {
    /// The bank built into danced.
    pub fn shipped() -> Result<PoseBank, PoseBankError> {
        let path = Path::new("configs/poses/bank.toml");
        Self::parse(
            SHIPPED_BANK_TOML,
            path,
            |_| Ok(SHIPPED_BANK_BVH.to_string()),
        )
    }

    /// Loads a bank from its TOML file (the BVH path inside is relative to it).
    pub fn load(path: &Path) -> Result<PoseBank, PoseBankError> {
        let text = std::fs::read_to_string(path).map_err(|source| PoseBankError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
        Self::parse(&text, path, |bvh| {
            let p = dir.join(bvh);
            std::fs::read_to_string(&p).map_err(|source| PoseBankError::Io { path: p, source })
        })
    }

    fn parse(
        text: &str,
        path: &Path,
        read_bvh: impl Fn(&str) -> Result<String, PoseBankError>,
    ) -> Result<PoseBank, PoseBankError> {
        let file: BankFile = toml::from_str(text).map_err(|e| PoseBankError::Toml {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        let bvh_path = path.with_file_name(&file.bvh);
        let bvh_err = |message: String| PoseBankError::Bvh {
            path: bvh_path.clone(),
            message,
        };
        let bvh = Bvh::parse(&read_bvh(&file.bvh)?).map_err(|e| bvh_err(e.to_string()))?;
        let poses = import(
            &bvh,
            &Skeleton::default_adult(),
            &RetargetOptions::default(),
        )
        .map_err(|e| bvh_err(e.to_string()))?
        .poses;
        let mut bank = PoseBank::default();
        for entry in file.pose {
            let fail = |message: String| PoseBankError::Pose {
                path: path.to_path_buf(),
                name: entry.name.clone(),
                message,
            };
            let Some(pose) = poses.get(entry.frame) else {
                return Err(fail(format!(
                    "frame {} is past the BVH's {} frames",
                    entry.frame,
                    poses.len()
                )));
            };
            if bank.get(&entry.name).is_some() {
                return Err(fail("named twice".into()));
            }
            if !pose.is_finite() {
                return Err(fail("the pose is not finite".into()));
            }
            bank.poses.push(NamedPose {
                name: entry.name.clone(),
                description: entry.description.clone(),
                rotations: pose.local_rotations,
            });
        }
        Ok(bank)
    }

    /// The pose called `name`.
    pub fn get(&self, name: &str) -> Option<&NamedPose> {
        self.poses.iter().find(|p| p.name == name)
    }

    /// Every pose, in file order.
    pub fn poses(&self) -> &[NamedPose] {
        &self.poses
    }
}

/// Picks `count` poses from `library` as far apart as possible (farthest-point sampling on
/// their [`body_shape`](model::body_shape::body_shape)s), deterministic.
pub fn pick_diverse_poses(library: &ClipLibrary, count: usize) -> Vec<Pose> {
    // Every 5th pose is plenty (clips move little in 0.2 s) and keeps this quick.
    let candidates: Vec<Pose> = library
        .poses
        .iter()
        .step_by(5)
        .map(|p| {
            let mut q = *p;
            let h = model::motion::heading(q.local_rotations[0]);
            q.local_rotations[0] = (model::motion::yaw(-h) * q.local_rotations[0]).normalize();
            q.root_position = Vec3::new(0.0, p.root_position.y, 0.0);
            q
        })
        .collect();
    let shapes: Vec<[Vec3; JOINT_COUNT]> = candidates
        .iter()
        .map(|p| model::body_shape::body_shape(&p.local_rotations))
        .collect();
    let dist = |a: &[Vec3; JOINT_COUNT], b: &[Vec3; JOINT_COUNT]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| x.distance_squared(*y))
            .sum::<f32>()
    };
    if shapes.is_empty() {
        return Vec::new();
    }
    // Start from the pose farthest from the mean shape: the most expressive one.
    let mut mean = [Vec3::ZERO; JOINT_COUNT];
    for s in &shapes {
        for (m, x) in mean.iter_mut().zip(s) {
            *m += *x / shapes.len() as f32;
        }
    }
    let mut best = vec![f32::INFINITY; shapes.len()];
    let first = (0..shapes.len())
        .max_by(|&a, &b| dist(&shapes[a], &mean).total_cmp(&dist(&shapes[b], &mean)))
        .unwrap_or(0);
    let mut picked = vec![first];
    while picked.len() < count.min(shapes.len()) {
        let last = *picked.last().unwrap_or(&first);
        for (i, s) in shapes.iter().enumerate() {
            best[i] = best[i].min(dist(s, &shapes[last]));
        }
        let next = (0..shapes.len())
            .max_by(|&a, &b| best[a].total_cmp(&best[b]))
            .unwrap_or(0);
        picked.push(next);
    }
    picked.into_iter().map(|i| candidates[i]).collect()
}

/// A few words on what a pose looks like (arms, stance), from its joint positions.
pub fn describe(pose: &Pose) -> String {
    let skeleton = Skeleton::default_adult();
    let mut w = [Vec3::ZERO; JOINT_COUNT];
    skeleton.world_positions(pose, &mut w);
    let arm = |hand: Joint, shoulder: Joint| {
        let (h, s) = (w[hand.index()], w[shoulder.index()]);
        if h.y > w[Joint::Head.index()].y {
            "up"
        } else if h.y > s.y - 0.15 {
            "out"
        } else if (h - s).length() < 0.45 {
            "bent"
        } else {
            "down"
        }
    };
    let hips = w[Joint::Hips.index()].y
        - w[Joint::LeftToes.index()]
            .y
            .min(w[Joint::RightToes.index()].y);
    let stance = if hips < 0.8 * skeleton.hip_height() {
        ", knees bent low"
    } else {
        ""
    };
    let lift = |toe: Joint, other: Joint| w[toe.index()].y > w[other.index()].y + 0.15;
    let feet = if lift(Joint::LeftToes, Joint::RightToes) {
        ", left foot lifted"
    } else if lift(Joint::RightToes, Joint::LeftToes) {
        ", right foot lifted"
    } else {
        ""
    };
    format!(
        "left arm {}, right arm {}{stance}{feet}",
        arm(Joint::LeftHand, Joint::LeftUpperArm),
        arm(Joint::RightHand, Joint::RightUpperArm)
    )
}

/// The TOML of a bank naming `poses` "pose-1", "pose-2", … in a BVH called `bvh_name`.
pub fn bank_toml(poses: &[Pose], bvh_name: &str) -> String {
    let mut s = format!(
        "# danced key-pose bank: names for the frames of {bvh_name} (any BVH rig works).\n\
         # Made by `danced library poses` from the shipped clip library (tang2018 training split):\n\
         # the poses farthest apart from each other. Rename them, reorder them or point `bvh` at\n\
         # your own file; MIDI maps and OSC /danced/control/keypose use these names.\n\
         bvh = \"{bvh_name}\"\n"
    );
    for (i, p) in poses.iter().enumerate() {
        s += &format!(
            "\n[[pose]]\nname = \"pose-{}\"\nframe = {i}\ndescription = \"{}\"\n",
            i + 1,
            describe(p)
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_bank_loads_sixteen_distinct_poses() {
        let bank = PoseBank::shipped().unwrap();
        assert_eq!(bank.poses().len(), 16);
        for i in 1..=16 {
            assert!(bank.get(&format!("pose-{i}")).is_some(), "pose-{i}");
        }
        let a = bank.get("pose-1").unwrap();
        let b = bank.get("pose-2").unwrap();
        let differ = (0..JOINT_COUNT)
            .filter(|&j| a.rotations[j].dot(b.rotations[j]).abs() < 0.99)
            .count();
        assert!(differ >= 3, "{differ} joints differ");
    }

    #[test]
    fn bad_banks_name_the_problem() {
        let dir = std::env::temp_dir().join(format!("danced-bank-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("bank.bvh"), SHIPPED_BANK_BVH).unwrap();
        let cases = [
            (
                "bvh = \"bank.bvh\"\n[[pose]]\nname = \"x\"\nframe = 99\n",
                "past the BVH",
            ),
            (
                "bvh = \"bank.bvh\"\n[[pose]]\nname = \"x\"\nframe = 0\n[[pose]]\nname = \"x\"\nframe = 1\n",
                "named twice",
            ),
            ("bvh = \"bank.bvh\"\ncolour = 1\n", "colour"),
            ("bvh = \"missing.bvh\"\n", "missing.bvh"),
        ];
        for (text, expected) in cases {
            let path = dir.join("bank.toml");
            std::fs::write(&path, text).unwrap();
            let err = PoseBank::load(&path).unwrap_err().to_string();
            assert!(err.contains(expected), "{err}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
