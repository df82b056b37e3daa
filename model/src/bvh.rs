//! BVH (Biovision Hierarchy) motion files: parsing, writing, forward kinematics, retargeting onto
//! our rig ([`retarget`]) and export of motion on our rig ([`export`]).
//!
//! # What a file means here
//!
//! - A joint's local transform is a translation then a rotation. The translation is its
//!   `OFFSET`, except that position channels, where present, replace the matching component
//!   (so a root's `Xposition Yposition Zposition` are its position in the parent's frame, the
//!   convention of Blender, MotionBuilder and the Bandai Namco data). Blender sets the missing
//!   components of a partial set of position channels to 0; we keep the `OFFSET`'s.
//! - Rotation channels are in degrees and compose in the order listed: for `Zrotation Xrotation
//!   Yrotation` the local rotation is `Rz · Rx · Ry` (a child-frame vector is turned by `Ry`
//!   first). Any order and any subset of the six channels per joint is accepted; each at most once.
//! - Lengths are in the file's unit (BVH does not say which; [`retarget`] guesses it).
//!
//! # Robustness
//!
//! [`Bvh::parse`] never panics: missing braces, unknown keywords, wrong channel counts,
//! non-numeric or non-finite numbers, frames with too few or too many values and a frame count
//! that does not match the header all give a [`ModelError::BvhSyntax`] with the 1-based line number.
//! The hierarchy is parsed without recursion, so deep nesting cannot overflow the stack, and
//! [`Bvh::read`] refuses files over [`MAX_FILE_BYTES`].

mod axes;
mod export;
mod names;
mod retarget;
#[cfg(test)]
mod tests;

use std::fmt;
use std::io::Write as _;
use std::path::Path;

use glam::{DQuat, DVec3, Quat, Vec3};

use crate::ModelError;

pub use axes::{AxisHints, DetectedAxes, describe_axes, detect_axes};
pub use export::{export, export_to_string};
pub use names::joint_for_name;
pub use retarget::{REQUIRED_JOINTS, RetargetOptions, Retargeted, import, retarget};

/// Largest file [`Bvh::read`] accepts, bytes (a 1 GiB BVH is ~100 M values, hours of motion).
pub const MAX_FILE_BYTES: u64 = 1 << 30;
/// Most joints a hierarchy may have; real skeletons have tens to a few hundred.
pub const MAX_JOINTS: usize = 10_000;

/// One animation channel of a joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Channel {
    /// Translation along the parent frame's X.
    Xposition,
    /// Translation along the parent frame's Y.
    Yposition,
    /// Translation along the parent frame's Z.
    Zposition,
    /// Rotation about X, degrees.
    Xrotation,
    /// Rotation about Y, degrees.
    Yrotation,
    /// Rotation about Z, degrees.
    Zrotation,
}

impl Channel {
    /// Every channel, positions first.
    pub const ALL: [Channel; 6] = [
        Channel::Xposition,
        Channel::Yposition,
        Channel::Zposition,
        Channel::Xrotation,
        Channel::Yrotation,
        Channel::Zrotation,
    ];

    /// The keyword as written in files, e.g. `"Zrotation"`.
    pub const fn name(self) -> &'static str {
        match self {
            Channel::Xposition => "Xposition",
            Channel::Yposition => "Yposition",
            Channel::Zposition => "Zposition",
            Channel::Xrotation => "Xrotation",
            Channel::Yrotation => "Yrotation",
            Channel::Zrotation => "Zrotation",
        }
    }

    /// The channel with this keyword (ASCII case-insensitive), `None` if unknown.
    pub fn from_name(name: &str) -> Option<Channel> {
        Channel::ALL
            .into_iter()
            .find(|c| c.name().eq_ignore_ascii_case(name))
    }

    /// The axis (0 = X, 1 = Y, 2 = Z) the channel moves or turns about.
    pub const fn axis(self) -> usize {
        match self {
            Channel::Xposition | Channel::Xrotation => 0,
            Channel::Yposition | Channel::Yrotation => 1,
            Channel::Zposition | Channel::Zrotation => 2,
        }
    }

    /// Whether this is a rotation channel.
    pub const fn is_rotation(self) -> bool {
        matches!(
            self,
            Channel::Xrotation | Channel::Yrotation | Channel::Zrotation
        )
    }
}

impl fmt::Display for Channel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One joint of a BVH hierarchy.
#[derive(Clone, Debug, PartialEq)]
pub struct BvhJoint {
    /// The name as in the file (spaces inside a name are kept).
    pub name: String,
    /// Index of the parent joint in [`Bvh::joints`], `None` for a root.
    pub parent: Option<usize>,
    /// Rest translation from the parent, file units.
    pub offset: Vec3,
    /// The animated channels, in the file's order.
    pub channels: Vec<Channel>,
    /// The `End Site` offset, if the joint has one.
    pub end_site: Option<Vec3>,
}

/// A parsed BVH file: hierarchy and motion.
#[derive(Clone, Debug, PartialEq)]
pub struct Bvh {
    /// Joints in file order; every parent comes before its children.
    pub joints: Vec<BvhJoint>,
    /// Seconds per frame (`Frame Time`).
    pub frame_time_s: f64,
    /// Channel values per frame, joints in file order and each joint's channels in its order.
    pub frames: Vec<Vec<f32>>,
}

/// Line-numbered whitespace-separated words of the hierarchy section.
struct Lexer<'a> {
    lines: std::iter::Peekable<std::iter::Enumerate<std::str::Lines<'a>>>,
    /// Words left on the current line and that line's 1-based number.
    current: Vec<&'a str>,
    line: usize,
}

impl<'a> Lexer<'a> {
    fn new(text: &'a str) -> Self {
        Lexer {
            lines: text.lines().enumerate().peekable(),
            current: Vec::new(),
            line: 0,
        }
    }

    fn error(&self, message: impl Into<String>) -> ModelError {
        ModelError::BvhSyntax {
            line: self.line.max(1),
            message: message.into(),
        }
    }

    /// Moves to the next line with words on it; false at the end of the text.
    fn fill(&mut self) -> bool {
        while self.current.is_empty() {
            let Some((i, l)) = self.lines.next() else {
                return false;
            };
            self.line = i + 1;
            // Reversed so that `pop` yields words in order.
            self.current = l.split_whitespace().rev().collect();
        }
        true
    }

    fn next_word(&mut self, what: &str) -> Result<&'a str, ModelError> {
        if !self.fill() {
            return Err(self.error(format!("file ends where {what} was expected")));
        }
        Ok(self.current.pop().expect("fill leaves a word"))
    }

    /// The words left on the current line (a joint name may contain spaces).
    fn rest_of_line(&mut self) -> Vec<&'a str> {
        let mut words = std::mem::take(&mut self.current);
        words.reverse();
        words
    }

    fn expect(&mut self, keyword: &str) -> Result<(), ModelError> {
        let w = self.next_word(&format!("{keyword:?}"))?;
        if w.eq_ignore_ascii_case(keyword) {
            Ok(())
        } else {
            Err(self.error(format!("expected {keyword:?}, found {w:?}")))
        }
    }

    fn number(&mut self, what: &str) -> Result<f32, ModelError> {
        let w = self.next_word(what)?;
        parse_finite(w).ok_or_else(|| self.error(format!("{what}: {w:?} is not a finite number")))
    }

    fn vec3(&mut self, what: &str) -> Result<Vec3, ModelError> {
        Ok(Vec3::new(
            self.number(what)?,
            self.number(what)?,
            self.number(what)?,
        ))
    }
}

/// `word` as a finite f32 (`NaN`, `inf` and values beyond f32's range are rejected).
fn parse_finite(word: &str) -> Option<f32> {
    word.parse::<f32>().ok().filter(|x| x.is_finite())
}

/// A joint under construction: which parts have been seen.
struct OpenJoint {
    index: usize,
    has_offset: bool,
    has_channels: bool,
}

impl Bvh {
    /// Parses BVH text.
    pub fn parse(text: &str) -> Result<Bvh, ModelError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut lex = Lexer::new(text);
        lex.expect("HIERARCHY")?;

        let mut joints: Vec<BvhJoint> = Vec::new();
        // Joints whose `}` has not been seen yet, innermost last.
        let mut open: Vec<OpenJoint> = Vec::new();
        loop {
            let word = lex.next_word("ROOT, JOINT, End Site, OFFSET, CHANNELS, } or MOTION")?;
            let keyword = word.to_ascii_lowercase();
            match keyword.as_str() {
                "root" | "joint" => {
                    if keyword == "root" && !open.is_empty() {
                        return Err(lex.error("ROOT inside another joint (use JOINT)"));
                    }
                    if keyword == "joint" && open.is_empty() {
                        return Err(lex.error("JOINT outside any ROOT"));
                    }
                    let mut words = lex.rest_of_line();
                    // `JOINT name {` on one line is seen in hand-written files.
                    let brace_on_line = words.last() == Some(&"{");
                    if brace_on_line {
                        words.pop();
                    }
                    if words.is_empty() {
                        return Err(lex.error(format!("{word} without a name")));
                    }
                    if joints.len() >= MAX_JOINTS {
                        return Err(lex.error(format!("more than {MAX_JOINTS} joints")));
                    }
                    let name = words.join(" ");
                    if !brace_on_line {
                        lex.expect("{")?;
                    }
                    joints.push(BvhJoint {
                        name,
                        parent: open.last().map(|j| j.index),
                        offset: Vec3::ZERO,
                        channels: Vec::new(),
                        end_site: None,
                    });
                    open.push(OpenJoint {
                        index: joints.len() - 1,
                        has_offset: false,
                        has_channels: false,
                    });
                }
                "offset" => {
                    let Some(current) = open.last_mut() else {
                        return Err(lex.error("OFFSET outside any joint"));
                    };
                    if current.has_offset {
                        return Err(lex.error("second OFFSET in one joint"));
                    }
                    current.has_offset = true;
                    let index = current.index;
                    joints[index].offset = lex.vec3("OFFSET value")?;
                }
                "channels" => {
                    let Some(current) = open.last_mut() else {
                        return Err(lex.error("CHANNELS outside any joint"));
                    };
                    if current.has_channels {
                        return Err(lex.error("second CHANNELS in one joint"));
                    }
                    current.has_channels = true;
                    let index = current.index;
                    let count_word = lex.next_word("the channel count")?;
                    let count: usize = count_word.parse().map_err(|_| {
                        lex.error(format!("channel count {count_word:?} is not a number"))
                    })?;
                    if count > 6 {
                        return Err(lex.error(format!("{count} channels (at most 6)")));
                    }
                    let names = lex.rest_of_line();
                    if names.len() != count {
                        return Err(lex.error(format!(
                            "CHANNELS {count} is followed by {} channel names",
                            names.len()
                        )));
                    }
                    let mut channels = Vec::with_capacity(count);
                    for name in names {
                        let channel = Channel::from_name(name)
                            .ok_or_else(|| lex.error(format!("unknown channel {name:?}")))?;
                        if channels.contains(&channel) {
                            return Err(lex.error(format!("channel {channel} listed twice")));
                        }
                        channels.push(channel);
                    }
                    joints[index].channels = channels;
                }
                "end" => {
                    let Some(current) = open.last() else {
                        return Err(lex.error("End Site outside any joint"));
                    };
                    let index = current.index;
                    let mut words = lex.rest_of_line();
                    let brace_on_line = words.last() == Some(&"{");
                    if brace_on_line {
                        words.pop();
                    }
                    // Some writers name the end site; the name means nothing.
                    if !words
                        .first()
                        .is_some_and(|w| w.eq_ignore_ascii_case("site"))
                    {
                        return Err(lex.error("expected \"End Site\""));
                    }
                    if joints[index].end_site.is_some() {
                        return Err(lex.error("second End Site in one joint"));
                    }
                    if !brace_on_line {
                        lex.expect("{")?;
                    }
                    lex.expect("OFFSET")?;
                    let offset = lex.vec3("End Site OFFSET value")?;
                    lex.expect("}")?;
                    joints[index].end_site = Some(offset);
                }
                "}" => {
                    let Some(closed) = open.pop() else {
                        return Err(lex.error("unmatched }"));
                    };
                    if !closed.has_offset {
                        return Err(lex.error(format!(
                            "joint {:?} has no OFFSET",
                            joints[closed.index].name
                        )));
                    }
                }
                "motion" => {
                    if let Some(unclosed) = open.last() {
                        return Err(lex.error(format!(
                            "MOTION before joint {:?} is closed (missing }})",
                            joints[unclosed.index].name
                        )));
                    }
                    if joints.is_empty() {
                        return Err(lex.error("no joints before MOTION"));
                    }
                    break;
                }
                _ => return Err(lex.error(format!("unexpected {word:?}"))),
            }
        }

        lex.expect("Frames:")?;
        let count_word = lex.next_word("the frame count")?;
        let frame_count: usize = count_word
            .parse()
            .map_err(|_| lex.error(format!("frame count {count_word:?} is not a number")))?;
        lex.expect("Frame")?;
        lex.expect("Time:")?;
        let time_word = lex.next_word("the frame time")?;
        let frame_time_s = time_word
            .parse::<f64>()
            .ok()
            .filter(|t| t.is_finite() && *t > 0.0)
            .ok_or_else(|| {
                lex.error(format!(
                    "frame time {time_word:?} is not a positive finite number"
                ))
            })?;
        if !lex.current.is_empty() {
            return Err(lex.error("unexpected values after the frame time"));
        }

        let width: usize = joints.iter().map(|j| j.channels.len()).sum();
        // Never trust the header's count for the allocation: a corrupt file could claim 10^18.
        let mut frames: Vec<Vec<f32>> = Vec::with_capacity(frame_count.min(1 << 16));
        for (i, l) in lex.lines.by_ref() {
            let line = i + 1;
            let mut values = Vec::with_capacity(width);
            for word in l.split_whitespace() {
                let v = parse_finite(word).ok_or_else(|| ModelError::BvhSyntax {
                    line,
                    message: format!("{word:?} is not a finite number"),
                })?;
                values.push(v);
            }
            if values.is_empty() {
                continue;
            }
            if frames.len() == frame_count {
                return Err(ModelError::BvhSyntax {
                    line,
                    message: format!("more frames than the {frame_count} the header says"),
                });
            }
            if values.len() != width {
                return Err(ModelError::BvhSyntax {
                    line,
                    message: format!(
                        "frame {} has {} values, the hierarchy has {width} channels",
                        frames.len() + 1,
                        values.len()
                    ),
                });
            }
            frames.push(values);
        }
        if frames.len() != frame_count {
            return Err(ModelError::BvhSyntax {
                line: text.lines().count().max(1),
                message: format!(
                    "file ends after {} of the {frame_count} frames the header says",
                    frames.len()
                ),
            });
        }
        Ok(Bvh {
            joints,
            frame_time_s,
            frames,
        })
    }

    /// Reads and parses a file; errors name it.
    pub fn read(path: impl AsRef<Path>) -> Result<Bvh, ModelError> {
        let path = path.as_ref();
        let io = |source| ModelError::Io {
            path: path.to_owned(),
            source,
        };
        let size = std::fs::metadata(path).map_err(io)?.len();
        if size > MAX_FILE_BYTES {
            return Err(ModelError::BvhTooLarge {
                path: path.to_owned(),
                bytes: size,
            });
        }
        let bytes = std::fs::read(path).map_err(io)?;
        let text = String::from_utf8(bytes).map_err(|e| ModelError::BvhInFile {
            path: path.to_owned(),
            source: Box::new(ModelError::BvhSyntax {
                line: 1 + e.as_bytes()[..e.utf8_error().valid_up_to()]
                    .iter()
                    .filter(|&&b| b == b'\n')
                    .count(),
                message: "not UTF-8 text".into(),
            }),
        })?;
        Bvh::parse(&text).map_err(|e| ModelError::BvhInFile {
            path: path.to_owned(),
            source: Box::new(e),
        })
    }

    /// Writes the file atomically: a temporary file beside it, then a rename. Fails without
    /// writing if the value does not pass [`Bvh::validate`].
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), ModelError> {
        let path = path.as_ref();
        self.validate()?;
        let io = |source| ModelError::Io {
            path: path.to_owned(),
            source,
        };
        let file_name = path
            .file_name()
            .ok_or_else(|| io(std::io::Error::other("not a file path")))?;
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(file_name);
        tmp_name.push(format!(".{}.tmp", std::process::id()));
        let tmp = path.with_file_name(tmp_name);
        let result = (|| {
            let mut file = std::fs::File::create(&tmp)?;
            file.write_all(self.to_string().as_bytes())?;
            file.sync_all()?;
            std::fs::rename(&tmp, path)
        })();
        if let Err(e) = result {
            let _ = std::fs::remove_file(&tmp);
            return Err(io(e));
        }
        Ok(())
    }

    /// Frames per second (`1 / Frame Time`).
    pub fn fps(&self) -> f64 {
        1.0 / self.frame_time_s
    }

    /// Number of channels per frame.
    pub fn channel_count(&self) -> usize {
        self.joints.iter().map(|j| j.channels.len()).sum()
    }

    /// Index of the first value of each joint's channels in a frame.
    pub fn channel_starts(&self) -> Vec<usize> {
        let mut start = 0;
        self.joints
            .iter()
            .map(|j| {
                let s = start;
                start += j.channels.len();
                s
            })
            .collect()
    }

    /// The joint named `name` (exactly), if any.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Each joint's children, in file order.
    pub fn children(&self) -> Vec<Vec<usize>> {
        let mut children = vec![Vec::new(); self.joints.len()];
        for (i, j) in self.joints.iter().enumerate() {
            // A parent out of range (a value built in code) leaves the joint out of every tree.
            if let Some(p) = j.parent.filter(|&p| p < children.len()) {
                children[p].push(i);
            }
        }
        children
    }

    /// Checks what [`Bvh::parse`] guarantees, for values built in code: parents before
    /// children, every frame as wide as the channels, finite numbers, a positive frame time.
    pub fn validate(&self) -> Result<(), ModelError> {
        let bad = |m: String| Err(ModelError::BvhInvalid(m));
        if !(self.frame_time_s.is_finite() && self.frame_time_s > 0.0) {
            return bad(format!("frame time {} s", self.frame_time_s));
        }
        for (i, j) in self.joints.iter().enumerate() {
            if j.parent.is_some_and(|p| p >= i) {
                return bad(format!("joint {:?} comes before its parent", j.name));
            }
            if !j.offset.is_finite() || j.end_site.is_some_and(|e| !e.is_finite()) {
                return bad(format!("joint {:?} has a non-finite offset", j.name));
            }
        }
        let width = self.channel_count();
        for (f, values) in self.frames.iter().enumerate() {
            if values.len() != width || values.iter().any(|v| !v.is_finite()) {
                return bad(format!(
                    "frame {f} has the wrong width or a non-finite value"
                ));
            }
        }
        Ok(())
    }

    /// The local rotation of `joint` in `frame`: its rotation channels composed in file order.
    ///
    /// Panics if `frame` or `joint` is out of range.
    pub fn local_rotation(&self, frame: usize, joint: usize) -> Quat {
        let start = self.channel_starts()[joint];
        self.local_rotation_at(&self.frames[frame], start, joint)
    }

    /// The translation of `joint` from its parent in `frame`: the offset with position
    /// channels replacing their components.
    ///
    /// Panics if `frame` or `joint` is out of range.
    pub fn local_translation(&self, frame: usize, joint: usize) -> Vec3 {
        let start = self.channel_starts()[joint];
        self.local_translation_at(&self.frames[frame], start, joint)
    }

    fn local_rotation_at(&self, values: &[f32], start: usize, joint: usize) -> Quat {
        // f64 so that composing three rotations adds no error visible at f32 precision.
        let mut q = DQuat::IDENTITY;
        for (k, channel) in self.joints[joint].channels.iter().enumerate() {
            let angle = f64::from(values[start + k]).to_radians();
            q *= match channel {
                Channel::Xrotation => DQuat::from_rotation_x(angle),
                Channel::Yrotation => DQuat::from_rotation_y(angle),
                Channel::Zrotation => DQuat::from_rotation_z(angle),
                _ => continue,
            };
        }
        q.normalize().as_quat()
    }

    fn local_translation_at(&self, values: &[f32], start: usize, joint: usize) -> Vec3 {
        let mut t = self.joints[joint].offset;
        for (k, channel) in self.joints[joint].channels.iter().enumerate() {
            if !channel.is_rotation() {
                t[channel.axis()] = values[start + k];
            }
        }
        t
    }

    /// World rotations and positions of every joint in `frame` (file units), into `rotations`
    /// and `positions` (resized to the joint count).
    ///
    /// Panics if `frame` is out of range.
    pub fn world_transforms(
        &self,
        frame: usize,
        rotations: &mut Vec<Quat>,
        positions: &mut Vec<Vec3>,
    ) {
        let values = &self.frames[frame];
        let starts = self.channel_starts();
        rotations.clear();
        positions.clear();
        let mut world: Vec<(DQuat, DVec3)> = Vec::with_capacity(self.joints.len());
        for (i, joint) in self.joints.iter().enumerate() {
            let local_r = self.local_rotation_at(values, starts[i], i).as_dquat();
            let local_t = self.local_translation_at(values, starts[i], i).as_dvec3();
            let (r, p) = match joint.parent {
                Some(parent) => {
                    let (pr, pp) = world[parent];
                    (pr * local_r, pp + pr * local_t)
                }
                None => (local_r, local_t),
            };
            world.push((r, p));
            rotations.push(r.as_quat());
            positions.push(p.as_vec3());
        }
    }

    /// World positions of every joint in `frame`, file units.
    ///
    /// Panics if `frame` is out of range.
    pub fn world_positions(&self, frame: usize) -> Vec<Vec3> {
        let mut rotations = Vec::new();
        let mut positions = Vec::new();
        self.world_transforms(frame, &mut rotations, &mut positions);
        positions
    }

    /// World positions of every joint with all channels at rest (offsets only), file units.
    pub fn rest_positions(&self) -> Vec<Vec3> {
        let mut positions: Vec<Vec3> = Vec::with_capacity(self.joints.len());
        for joint in &self.joints {
            let p = match joint.parent {
                Some(parent) => positions[parent] + joint.offset,
                None => joint.offset,
            };
            positions.push(p);
        }
        positions
    }
}

/// Indentation for nesting `depth`, capped so that a deep chain does not grow quadratically.
fn indent(depth: usize) -> String {
    "  ".repeat(depth.min(32))
}

impl fmt::Display for Bvh {
    /// The file text. Numbers are written in Rust's shortest round-trip form, so parsing the
    /// text gives back exactly the same values (for a value that passes [`Bvh::validate`]).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let children = self.children();
        let starts = self.channel_starts();
        // The motion lines list channels in hierarchy (depth-first) order, which need not be
        // the order of `joints` for a value built in code.
        let mut order = Vec::with_capacity(self.joints.len());
        writeln!(f, "HIERARCHY")?;
        // Explicit stack: (joint, whether its children have been written).
        let mut stack: Vec<(usize, bool)> = self
            .joints
            .iter()
            .enumerate()
            .filter(|(_, j)| j.parent.is_none())
            .map(|(i, _)| (i, false))
            .rev()
            .collect();
        let mut depth = 0usize;
        while let Some((i, done)) = stack.pop() {
            let joint = &self.joints[i];
            if done {
                if let Some(e) = joint.end_site {
                    let pad = indent(depth);
                    writeln!(f, "{pad}End Site")?;
                    writeln!(f, "{pad}{{")?;
                    writeln!(f, "{pad}  OFFSET {} {} {}", e.x, e.y, e.z)?;
                    writeln!(f, "{pad}}}")?;
                }
                depth -= 1;
                writeln!(f, "{}}}", indent(depth))?;
                continue;
            }
            order.push(i);
            let pad = indent(depth);
            let keyword = if joint.parent.is_none() {
                "ROOT"
            } else {
                "JOINT"
            };
            writeln!(f, "{pad}{keyword} {}", joint.name)?;
            writeln!(f, "{pad}{{")?;
            let o = joint.offset;
            writeln!(f, "{pad}  OFFSET {} {} {}", o.x, o.y, o.z)?;
            write!(f, "{pad}  CHANNELS {}", joint.channels.len())?;
            for c in &joint.channels {
                write!(f, " {c}")?;
            }
            writeln!(f)?;
            depth += 1;
            stack.push((i, true));
            for &c in children[i].iter().rev() {
                stack.push((c, false));
            }
        }
        writeln!(f, "MOTION")?;
        writeln!(f, "Frames: {}", self.frames.len())?;
        writeln!(f, "Frame Time: {}", self.frame_time_s)?;
        for values in &self.frames {
            let mut first = true;
            for &j in &order {
                let start = starts[j];
                // A frame of the wrong width (a value built in code) is written short, not a panic.
                let own = values
                    .get(start..start + self.joints[j].channels.len())
                    .unwrap_or(&[]);
                for v in own {
                    if !first {
                        f.write_str(" ")?;
                    }
                    first = false;
                    write!(f, "{v}")?;
                }
            }
            writeln!(f)?;
        }
        Ok(())
    }
}
