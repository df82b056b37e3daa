//! Which of our joints each joint of a BVH drives, from its name and its place in the hierarchy.
//!
//! Names are recognised in four passes, each only filling joints the passes before left free,
//! and within a pass the first source joint (file order: parents first) for a joint wins:
//!
//! 1. the user's map ([`super::RetargetOptions::names`]);
//! 2. the tables of the naming conventions users meet (Unity humanoid, i.e. our own names;
//!    Mixamo; CMU's ASF names; AMASS's BVH re-exports of CMU; SMPL; Unreal; 3ds Max Biped;
//!    Rokoko; Bandai Namco), the convention matching most of the file's names first, so a name
//!    two conventions read differently (SMPL's `left_foot` is the toes, Mixamo's `LeftFoot` the
//!    ankle) is read the file's way;
//! 3. the name's parts (a side — `l`, `left`, `_L`, `.L`, a leading `l` as in `lfemur` — and a
//!    body part with its common synonyms: thigh, femur, upleg, shin, calf, tibia, collar, …),
//!    with the ambiguous parts settled by what else the file holds on that side (`shoulder` is
//!    the upper arm below a `clavicle` or `collar`, the clavicle otherwise; `foot` is the toes
//!    below an `ankle`);
//! 4. the hierarchy: the joints on the path from the hips to where the neck and arms branch
//!    become the spine (lowest), chest and upper chest (the branching one), the first joint
//!    between there and the head the neck; a root joint named `root` drives the hips when
//!    nothing else does.

use crate::rig::{JOINT_COUNT, Joint};

use super::Bvh;

/// One naming convention's table: normalised names ([`normalise`]) and the joints they drive.
struct Convention {
    /// What users call it.
    name: &'static str,
    /// Normalised source names and our joints; empty for our own names ([`Joint::name`]).
    table: &'static [(&'static str, Joint)],
}

impl Convention {
    /// The joint the normalised name `key` drives in this convention.
    fn lookup(&self, key: &str) -> Option<Joint> {
        if self.table.is_empty() {
            return Joint::from_name(key);
        }
        self.table.iter().find(|(n, _)| *n == key).map(|&(_, j)| j)
    }
}

use Joint::*;

/// The conventions with tables, in the order they break ties.
const CONVENTIONS: &[Convention] = &[
    Convention {
        name: "Unity humanoid",
        // Our own joints' names (`Joint::name`).
        table: &[],
    },
    Convention {
        name: "Mixamo",
        table: &[
            ("hips", Hips),
            ("spine", Spine),
            ("spine1", Chest),
            ("spine2", UpperChest),
            ("neck", Neck),
            ("head", Head),
            ("leftshoulder", LeftShoulder),
            ("leftarm", LeftUpperArm),
            ("leftforearm", LeftLowerArm),
            ("lefthand", LeftHand),
            ("rightshoulder", RightShoulder),
            ("rightarm", RightUpperArm),
            ("rightforearm", RightLowerArm),
            ("righthand", RightHand),
            ("leftupleg", LeftUpperLeg),
            ("leftleg", LeftLowerLeg),
            ("leftfoot", LeftFoot),
            ("lefttoebase", LeftToes),
            ("rightupleg", RightUpperLeg),
            ("rightleg", RightLowerLeg),
            ("rightfoot", RightFoot),
            ("righttoebase", RightToes),
        ],
    },
    Convention {
        name: "CMU (ASF)",
        table: &[
            ("root", Hips),
            ("lowerback", Spine),
            ("upperback", Chest),
            ("thorax", UpperChest),
            ("lowerneck", Neck),
            ("head", Head),
            ("lclavicle", LeftShoulder),
            ("lhumerus", LeftUpperArm),
            ("lradius", LeftLowerArm),
            ("lwrist", LeftHand),
            ("rclavicle", RightShoulder),
            ("rhumerus", RightUpperArm),
            ("rradius", RightLowerArm),
            ("rwrist", RightHand),
            ("lfemur", LeftUpperLeg),
            ("ltibia", LeftLowerLeg),
            ("lfoot", LeftFoot),
            ("ltoes", LeftToes),
            ("rfemur", RightUpperLeg),
            ("rtibia", RightLowerLeg),
            ("rfoot", RightFoot),
            ("rtoes", RightToes),
        ],
    },
    Convention {
        name: "AMASS (CMU re-export)",
        table: &[
            ("root", Hips),
            ("lowerback", Spine),
            ("upperback", Chest),
            ("chest", UpperChest),
            ("lowerneck", Neck),
            ("upperneck", Head),
            ("lclavicle", LeftShoulder),
            ("lshoulder", LeftUpperArm),
            ("lelbow", LeftLowerArm),
            ("lwrist", LeftHand),
            ("rclavicle", RightShoulder),
            ("rshoulder", RightUpperArm),
            ("relbow", RightLowerArm),
            ("rwrist", RightHand),
            ("lhip", LeftUpperLeg),
            ("lknee", LeftLowerLeg),
            ("lankle", LeftFoot),
            ("ltoe", LeftToes),
            ("rhip", RightUpperLeg),
            ("rknee", RightLowerLeg),
            ("rankle", RightFoot),
            ("rtoe", RightToes),
        ],
    },
    Convention {
        name: "SMPL",
        table: &[
            ("pelvis", Hips),
            ("spine1", Spine),
            ("spine2", Chest),
            ("spine3", UpperChest),
            ("neck", Neck),
            ("head", Head),
            ("leftcollar", LeftShoulder),
            ("leftshoulder", LeftUpperArm),
            ("leftelbow", LeftLowerArm),
            ("leftwrist", LeftHand),
            ("rightcollar", RightShoulder),
            ("rightshoulder", RightUpperArm),
            ("rightelbow", RightLowerArm),
            ("rightwrist", RightHand),
            ("lefthip", LeftUpperLeg),
            ("leftknee", LeftLowerLeg),
            ("leftankle", LeftFoot),
            ("leftfoot", LeftToes),
            ("righthip", RightUpperLeg),
            ("rightknee", RightLowerLeg),
            ("rightankle", RightFoot),
            ("rightfoot", RightToes),
            ("lcollar", LeftShoulder),
            ("lshoulder", LeftUpperArm),
            ("lelbow", LeftLowerArm),
            ("lwrist", LeftHand),
            ("rcollar", RightShoulder),
            ("rshoulder", RightUpperArm),
            ("relbow", RightLowerArm),
            ("rwrist", RightHand),
            ("lhip", LeftUpperLeg),
            ("lknee", LeftLowerLeg),
            ("lankle", LeftFoot),
            ("lfoot", LeftToes),
            ("rhip", RightUpperLeg),
            ("rknee", RightLowerLeg),
            ("rankle", RightFoot),
            ("rfoot", RightToes),
        ],
    },
    Convention {
        name: "Unreal",
        table: &[
            ("pelvis", Hips),
            ("spine01", Spine),
            ("spine02", Chest),
            ("spine03", UpperChest),
            ("neck01", Neck),
            ("head", Head),
            ("claviclel", LeftShoulder),
            ("upperarml", LeftUpperArm),
            ("lowerarml", LeftLowerArm),
            ("handl", LeftHand),
            ("clavicler", RightShoulder),
            ("upperarmr", RightUpperArm),
            ("lowerarmr", RightLowerArm),
            ("handr", RightHand),
            ("thighl", LeftUpperLeg),
            ("calfl", LeftLowerLeg),
            ("footl", LeftFoot),
            ("balll", LeftToes),
            ("thighr", RightUpperLeg),
            ("calfr", RightLowerLeg),
            ("footr", RightFoot),
            ("ballr", RightToes),
        ],
    },
    Convention {
        name: "3ds Max Biped",
        table: &[
            ("pelvis", Hips),
            ("spine", Spine),
            ("spine1", Chest),
            ("spine2", UpperChest),
            ("neck", Neck),
            ("head", Head),
            ("lclavicle", LeftShoulder),
            ("lupperarm", LeftUpperArm),
            ("lforearm", LeftLowerArm),
            ("lhand", LeftHand),
            ("rclavicle", RightShoulder),
            ("rupperarm", RightUpperArm),
            ("rforearm", RightLowerArm),
            ("rhand", RightHand),
            ("lthigh", LeftUpperLeg),
            ("lcalf", LeftLowerLeg),
            ("lfoot", LeftFoot),
            ("ltoe0", LeftToes),
            ("rthigh", RightUpperLeg),
            ("rcalf", RightLowerLeg),
            ("rfoot", RightFoot),
            ("rtoe0", RightToes),
        ],
    },
    Convention {
        name: "Rokoko",
        table: &[
            ("hips", Hips),
            ("neck", Neck),
            ("head", Head),
            ("leftshoulder", LeftShoulder),
            ("leftarm", LeftUpperArm),
            ("leftforearm", LeftLowerArm),
            ("lefthand", LeftHand),
            ("rightshoulder", RightShoulder),
            ("rightarm", RightUpperArm),
            ("rightforearm", RightLowerArm),
            ("righthand", RightHand),
            ("leftthigh", LeftUpperLeg),
            ("leftshin", LeftLowerLeg),
            ("leftfoot", LeftFoot),
            ("lefttoe", LeftToes),
            ("rightthigh", RightUpperLeg),
            ("rightshin", RightLowerLeg),
            ("rightfoot", RightFoot),
            ("righttoe", RightToes),
        ],
    },
    Convention {
        name: "Bandai Namco",
        table: &[
            ("hips", Hips),
            ("spine", Spine),
            ("chest", Chest),
            ("neck", Neck),
            ("head", Head),
            ("shoulderl", LeftShoulder),
            ("upperarml", LeftUpperArm),
            ("lowerarml", LeftLowerArm),
            ("handl", LeftHand),
            ("shoulderr", RightShoulder),
            ("upperarmr", RightUpperArm),
            ("lowerarmr", RightLowerArm),
            ("handr", RightHand),
            ("upperlegl", LeftUpperLeg),
            ("lowerlegl", LeftLowerLeg),
            ("footl", LeftFoot),
            ("toesl", LeftToes),
            ("upperlegr", RightUpperLeg),
            ("lowerlegr", RightLowerLeg),
            ("footr", RightFoot),
            ("toesr", RightToes),
        ],
    },
];

/// `name` without a namespace prefix (`mixamorig:Hips` → `Hips`, `Armature|Hips` → `Hips`) and
/// surrounding space.
pub(crate) fn strip_namespace(name: &str) -> &str {
    let name = name.trim();
    name.rsplit_once([':', '|']).map_or(name, |(_, n)| n)
}

/// The name as the tables hold it: namespace removed, lower case, letters and digits only, and
/// a 3ds Max `Bip01`-style prefix removed (`Bip01 L Thigh` → `lthigh`, `spine_01` → `spine01`).
pub(crate) fn normalise(name: &str) -> String {
    let key: String = strip_namespace(name)
        .chars()
        .filter(char::is_ascii_alphanumeric)
        .map(|c| c.to_ascii_lowercase())
        .collect();
    strip_biped_prefix(&key).to_owned()
}

/// `key` without a leading `bip` + digits (3ds Max Biped's root name) when more follows.
fn strip_biped_prefix(key: &str) -> &str {
    if let Some(rest) = key.strip_prefix("bip") {
        let digits = rest.len() - rest.trim_start_matches(|c: char| c.is_ascii_digit()).len();
        if digits > 0 && rest.len() > digits {
            return &rest[digits..];
        }
    }
    key
}

/// Which side of the body a name is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    Left,
    Right,
    Centre,
}

/// A body part a name can say, before ambiguities are settled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Part {
    Hips,
    Spine,
    Neck,
    Head,
    Clavicle,
    /// `shoulder`: the clavicle, or the upper arm below a clavicle.
    Shoulder,
    UpperArm,
    LowerArm,
    Wrist,
    Hand,
    UpperLeg,
    LowerLeg,
    Ankle,
    /// `foot`: the ankle, or the toes below an ankle.
    Foot,
    Toes,
}

/// Part words (letters only, lower case) and what they say; `hip` with a side is the upper leg.
const PART_WORDS: &[(&str, Part)] = &[
    ("hips", Part::Hips),
    ("pelvis", Part::Hips),
    ("spine", Part::Spine),
    ("chest", Part::Spine),
    ("upperchest", Part::Spine),
    ("lowerback", Part::Spine),
    ("upperback", Part::Spine),
    ("back", Part::Spine),
    ("thorax", Part::Spine),
    ("torso", Part::Spine),
    ("abdomen", Part::Spine),
    ("abs", Part::Spine),
    ("waist", Part::Spine),
    ("belly", Part::Spine),
    ("neck", Part::Neck),
    ("lowerneck", Part::Neck),
    ("upperneck", Part::Neck),
    ("head", Part::Head),
    ("clavicle", Part::Clavicle),
    ("collar", Part::Clavicle),
    ("collarbone", Part::Clavicle),
    ("shoulder", Part::Shoulder),
    ("upperarm", Part::UpperArm),
    ("uparm", Part::UpperArm),
    ("arm", Part::UpperArm),
    ("humerus", Part::UpperArm),
    ("bicep", Part::UpperArm),
    ("forearm", Part::LowerArm),
    ("lowerarm", Part::LowerArm),
    ("lowarm", Part::LowerArm),
    ("elbow", Part::LowerArm),
    ("radius", Part::LowerArm),
    ("ulna", Part::LowerArm),
    ("wrist", Part::Wrist),
    ("hand", Part::Hand),
    ("hip", Part::UpperLeg),
    ("thigh", Part::UpperLeg),
    ("femur", Part::UpperLeg),
    ("upleg", Part::UpperLeg),
    ("upperleg", Part::UpperLeg),
    ("leg", Part::LowerLeg),
    ("lowerleg", Part::LowerLeg),
    ("lowleg", Part::LowerLeg),
    ("knee", Part::LowerLeg),
    ("calf", Part::LowerLeg),
    ("shin", Part::LowerLeg),
    ("tibia", Part::LowerLeg),
    ("crus", Part::LowerLeg),
    ("ankle", Part::Ankle),
    ("foot", Part::Foot),
    ("toe", Part::Toes),
    ("toes", Part::Toes),
    ("toebase", Part::Toes),
    ("ball", Part::Toes),
];

/// Tokens that name no part (rig prefixes and filler).
const FILLER: &[&str] = &[
    "bip",
    "mixamorig",
    "def",
    "jnt",
    "joint",
    "bone",
    "bn",
    "b",
    "j",
];

/// A name's words: split at non-alphanumerics, lower-to-upper case changes and letter–digit
/// changes (`LeftUpLeg_01` → `left up leg 01`), lower case.
fn words(name: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut current = String::new();
    let mut previous: Option<char> = None;
    for c in strip_namespace(name).chars() {
        if !c.is_ascii_alphanumeric() {
            if !current.is_empty() {
                out.push(std::mem::take(&mut current));
            }
            previous = None;
            continue;
        }
        if let Some(p) = previous {
            let case_change = p.is_ascii_lowercase() && c.is_ascii_uppercase();
            let digit_change = p.is_ascii_digit() != c.is_ascii_digit();
            if (case_change || digit_change) && !current.is_empty() {
                out.push(std::mem::take(&mut current));
            }
        }
        current.push(c.to_ascii_lowercase());
        previous = Some(c);
    }
    if !current.is_empty() {
        out.push(current);
    }
    out
}

/// The part word `w` is, if any.
fn part_word(w: &str) -> Option<Part> {
    PART_WORDS.iter().find(|(n, _)| *n == w).map(|&(_, p)| p)
}

/// The side and part a name says, if it says a part.
fn side_and_part(name: &str) -> Option<(Side, Part)> {
    let mut side = Side::Centre;
    let mut rest: Vec<String> = Vec::new();
    for w in words(name) {
        match w.as_str() {
            "l" | "left" | "lt" => side = Side::Left,
            "r" | "right" | "rt" => side = Side::Right,
            w if w.chars().all(|c| c.is_ascii_digit()) => {}
            w if FILLER.contains(&w) => {}
            _ => rest.push(w),
        }
    }
    let joined: String = rest.concat();
    if joined.is_empty() {
        return None;
    }
    // A side glued to the part: `lfemur`, `rhip`.
    if side == Side::Centre {
        for (prefix, s) in [
            ("left", Side::Left),
            ("right", Side::Right),
            ("l", Side::Left),
            ("r", Side::Right),
        ] {
            if part_word(&joined).is_none()
                && let Some(part) = joined.strip_prefix(prefix).and_then(part_word)
            {
                return Some((s, part));
            }
        }
    }
    // The part is the name's last words; what comes before is a rig's prefix (`CC_Base_`).
    (0..rest.len()).find_map(|k| part_word(&rest[k..].concat()).map(|part| (side, part)))
}

/// How a file's joint names were read.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct NameMatch {
    /// Our joint each source joint drives (`None`: none).
    pub driven: Vec<Option<Joint>>,
    /// The convention whose table matched most names ("names by their parts" when none did).
    pub convention: &'static str,
}

/// Our joint a single source name drives by the conventions' tables (in their tie order) or
/// its parts, without the file around it; `None` if none.
pub fn joint_for_name(name: &str) -> Option<Joint> {
    let key = normalise(name);
    CONVENTIONS
        .iter()
        .find_map(|c| c.lookup(&key))
        .filter(|_| key != "root")
        .or_else(|| match side_and_part(name)? {
            (Side::Centre, Part::Hips) => Some(Hips),
            (Side::Centre, Part::Neck) => Some(Neck),
            (Side::Centre, Part::Head) => Some(Head),
            (Side::Left, part) => limb_joint(part).map(|(l, _)| l),
            (Side::Right, part) => limb_joint(part).map(|(_, r)| r),
            _ => None,
        })
}

/// The left and right joints a limb part drives when nothing around it says otherwise.
fn limb_joint(part: Part) -> Option<(Joint, Joint)> {
    Some(match part {
        Part::Clavicle | Part::Shoulder => (LeftShoulder, RightShoulder),
        Part::UpperArm => (LeftUpperArm, RightUpperArm),
        Part::LowerArm => (LeftLowerArm, RightLowerArm),
        Part::Wrist | Part::Hand => (LeftHand, RightHand),
        Part::UpperLeg => (LeftUpperLeg, RightUpperLeg),
        Part::LowerLeg => (LeftLowerLeg, RightLowerLeg),
        Part::Ankle | Part::Foot => (LeftFoot, RightFoot),
        Part::Toes => (LeftToes, RightToes),
        Part::Hips | Part::Spine | Part::Neck | Part::Head => return None,
    })
}

/// Reads the joint names of `bvh`; see the module documentation.
pub(crate) fn match_joints(bvh: &Bvh, user: &[(String, Joint)]) -> NameMatch {
    let n = bvh.joints.len();
    let mut driven: Vec<Option<Joint>> = vec![None; n];
    let mut taken = [false; JOINT_COUNT];
    let mut assign = |driven: &mut Vec<Option<Joint>>, i: usize, j: Joint| {
        if driven[i].is_none() && !taken[j.index()] {
            driven[i] = Some(j);
            taken[j.index()] = true;
        }
    };
    let keys: Vec<String> = bvh.joints.iter().map(|j| normalise(&j.name)).collect();

    // 1. The user's map.
    for (i, joint) in bvh.joints.iter().enumerate() {
        let name = strip_namespace(&joint.name);
        if let Some(&(_, j)) = user
            .iter()
            .find(|(n, _)| strip_namespace(n).eq_ignore_ascii_case(name))
        {
            assign(&mut driven, i, j);
        }
    }

    // 2. The conventions' tables, the best-matching first.
    let score = |c: &Convention| keys.iter().filter(|k| c.lookup(k).is_some()).count();
    let mut order: Vec<(usize, &Convention)> = CONVENTIONS.iter().enumerate().collect();
    order.sort_by_key(|&(i, c)| (std::cmp::Reverse(score(c)), i));
    let best = order.first().map(|&(_, c)| c).filter(|c| score(c) >= 3);
    for (_, convention) in &order {
        for (i, key) in keys.iter().enumerate() {
            // `root` drives the hips only when nothing else does (step 4): Unreal's root is
            // on the floor under the pelvis.
            if let Some(j) = convention.lookup(key)
                && !(j == Hips && key == "root")
            {
                assign(&mut driven, i, j);
            }
        }
    }

    // 3. The names' parts.
    let parts: Vec<Option<(Side, Part)>> =
        bvh.joints.iter().map(|j| side_and_part(&j.name)).collect();
    let has = |side: Side, part: Part| parts.iter().flatten().any(|&(s, p)| s == side && p == part);
    for (i, sp) in parts.iter().enumerate() {
        let Some((side, part)) = *sp else { continue };
        let limb = |left: Joint, right: Joint| match side {
            Side::Left => Some(left),
            Side::Right => Some(right),
            Side::Centre => None,
        };
        let ours = match part {
            Part::Hips => (side == Side::Centre).then_some(Hips),
            Part::Spine => None,
            Part::Neck => (side == Side::Centre).then_some(Neck),
            Part::Head => (side == Side::Centre).then_some(Head),
            Part::Clavicle => limb(LeftShoulder, RightShoulder),
            Part::Shoulder if has(side, Part::Clavicle) => limb(LeftUpperArm, RightUpperArm),
            Part::Shoulder => limb(LeftShoulder, RightShoulder),
            Part::UpperArm => limb(LeftUpperArm, RightUpperArm),
            Part::LowerArm => limb(LeftLowerArm, RightLowerArm),
            Part::Wrist => limb(LeftHand, RightHand),
            Part::Hand if has(side, Part::Wrist) => None,
            Part::Hand => limb(LeftHand, RightHand),
            Part::UpperLeg => limb(LeftUpperLeg, RightUpperLeg),
            Part::LowerLeg => limb(LeftLowerLeg, RightLowerLeg),
            Part::Ankle => limb(LeftFoot, RightFoot),
            Part::Foot if has(side, Part::Ankle) => limb(LeftToes, RightToes),
            Part::Foot => limb(LeftFoot, RightFoot),
            Part::Toes => limb(LeftToes, RightToes),
        };
        if let Some(j) = ours {
            assign(&mut driven, i, j);
        }
    }

    // 4. The hierarchy.
    let root_named_root = bvh
        .joints
        .iter()
        .position(|j| j.parent.is_none() && normalise(&j.name) == "root");
    if let Some(r) = root_named_root {
        assign(&mut driven, r, Hips);
    }
    fill_from_hierarchy(bvh, &mut driven, &mut taken);

    let convention = best.map_or("names by their parts", |c| c.name);
    NameMatch { driven, convention }
}

/// Source joints from `i` up to the root, `i` first.
fn ancestors(bvh: &Bvh, mut i: usize) -> Vec<usize> {
    let mut out = vec![i];
    while let Some(p) = bvh.joints[i].parent {
        out.push(p);
        i = p;
    }
    out
}

/// Step 4 of the module documentation: the spine, chest, upper chest and neck from the path
/// between the hips and where the neck and arms branch.
fn fill_from_hierarchy(bvh: &Bvh, driven: &mut [Option<Joint>], taken: &mut [bool; JOINT_COUNT]) {
    let find = |driven: &[Option<Joint>], j: Joint| driven.iter().position(|&d| d == Some(j));
    let Some(hips) = find(driven, Hips) else {
        return;
    };
    // The topmost mapped joint of the neck or head and of each arm.
    let tops: Vec<usize> = [
        [Neck, Head],
        [LeftShoulder, LeftUpperArm],
        [RightShoulder, RightUpperArm],
    ]
    .iter()
    .filter_map(|pair| pair.iter().find_map(|&j| find(driven, j)))
    .collect();
    if tops.len() < 2 {
        return;
    }
    // Where they branch: the deepest common ancestor (excluding the tops themselves).
    let chains: Vec<Vec<usize>> = tops
        .iter()
        .map(|&t| ancestors(bvh, t).into_iter().skip(1).collect())
        .collect();
    let Some(&branch) = chains[0]
        .iter()
        .find(|a| chains[1..].iter().all(|c| c.contains(a)))
    else {
        return;
    };
    // The path from just above the hips to the branch, lowest first.
    let up: Vec<usize> = ancestors(bvh, branch);
    let Some(h) = up.iter().position(|&a| a == hips) else {
        return;
    };
    let path: Vec<usize> = up[..h].iter().rev().copied().collect();
    // A spine longer than a table knew (UE5's five bones against UE4's three) leaves the
    // branching joint free: the path is shared out again, ends first.
    if path.last().is_some_and(|&b| driven[b].is_none()) {
        for &i in &path {
            if let Some(j @ (Spine | Chest | UpperChest)) = driven[i] {
                driven[i] = None;
                taken[j.index()] = false;
            }
        }
    }
    let mut put = |driven: &mut [Option<Joint>], i: usize, j: Joint| {
        if driven[i].is_none() && !taken[j.index()] {
            driven[i] = Some(j);
            taken[j.index()] = true;
        }
    };
    if let Some(&top) = path.last() {
        put(driven, top, UpperChest);
    }
    if path.len() >= 2 {
        put(driven, path[0], Spine);
    }
    if path.len() >= 3 {
        put(driven, path[path.len() - 2], Chest);
    }
    // The neck: the first joint between the branch and the head.
    if let Some(head) = find(driven, Head) {
        let above: Vec<usize> = ancestors(bvh, head).into_iter().skip(1).collect();
        if let Some(b) = above.iter().position(|&a| a == branch)
            && b >= 1
        {
            put(driven, above[b - 1], Neck);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::BvhJoint;
    use glam::Vec3;

    #[test]
    fn names_split_into_a_side_and_a_part() {
        for (name, side, part) in [
            ("LeftUpLeg", Side::Left, Part::UpperLeg),
            ("mixamorig:RightForeArm", Side::Right, Part::LowerArm),
            ("Bip01 L Thigh", Side::Left, Part::UpperLeg),
            ("thigh_l", Side::Left, Part::UpperLeg),
            ("DEF-shin.R", Side::Right, Part::LowerLeg),
            ("lfemur", Side::Left, Part::UpperLeg),
            ("rhip", Side::Right, Part::UpperLeg),
            ("L_Collar", Side::Left, Part::Clavicle),
            ("left_shoulder", Side::Left, Part::Shoulder),
            ("spine_03", Side::Centre, Part::Spine),
            ("Pelvis", Side::Centre, Part::Hips),
        ] {
            assert_eq!(side_and_part(name), Some((side, part)), "{name}");
        }
        // Extra words make it no part: end bones and fingers stay unmapped.
        for name in [
            "RightToe_End",
            "LeftHandThumb1",
            "joint_Root",
            "LeftEye",
            "Tail",
        ] {
            assert_eq!(side_and_part(name), None, "{name}");
        }
        assert_eq!(normalise("Bip01 L Toe0"), "ltoe0");
        assert_eq!(normalise("mixamorig:Spine1"), "spine1");
        assert_eq!(normalise("spine_01"), "spine01");
    }

    /// A hierarchy from `(name, parent name)` pairs, parents first (offsets are not read).
    fn hierarchy(joints: &[(&str, &str)]) -> Bvh {
        let mut out: Vec<BvhJoint> = Vec::new();
        for &(name, parent) in joints {
            let parent = out.iter().position(|j| j.name == parent);
            out.push(BvhJoint {
                name: name.into(),
                parent,
                offset: Vec3::Y,
                channels: Vec::new(),
                end_site: None,
            });
        }
        Bvh {
            joints: out,
            frame_time_s: 1.0 / 30.0,
            frames: Vec::new(),
        }
    }

    /// Our joint driven by each named source joint; every joint of ours must be driven.
    fn check(convention: &str, joints: &[(&str, &str)], expected: &[(&str, Joint)]) {
        let bvh = hierarchy(joints);
        let found = match_joints(&bvh, &[]);
        assert_eq!(found.convention, convention);
        for &(name, joint) in expected {
            let i = bvh.joints.iter().position(|j| j.name == name).unwrap();
            assert_eq!(found.driven[i], Some(joint), "{convention}: {name}");
        }
        for joint in Joint::ALL {
            assert!(
                found.driven.contains(&Some(joint)),
                "{convention}: nothing drives {joint}"
            );
        }
        let drivers = found.driven.iter().flatten().count();
        assert_eq!(drivers, JOINT_COUNT, "{convention}: one driver per joint");
    }

    /// A limb chain on both sides: `(name with {s} for the side, parent with {s})`.
    fn sides<'a>(chain: &[(&'a str, &'a str)], left: &str, right: &str) -> Vec<(String, String)> {
        let mut out = Vec::new();
        for side in [left, right] {
            for (n, p) in chain {
                out.push((n.replace("{s}", side), p.replace("{s}", side)));
            }
        }
        out
    }

    fn owned(v: &[(String, String)]) -> Vec<(&str, &str)> {
        v.iter().map(|(a, b)| (a.as_str(), b.as_str())).collect()
    }

    #[test]
    fn the_common_conventions_map_every_joint() {
        // CMU's ASF names as BVH converters keep them: a hip-joint offset bone under the root,
        // hands and fingers below the wrists, two neck joints.
        let mut cmu = vec![
            ("root".to_owned(), String::new()),
            ("lowerback".into(), "root".into()),
            ("upperback".into(), "lowerback".into()),
            ("thorax".into(), "upperback".into()),
            ("lowerneck".into(), "thorax".into()),
            ("upperneck".into(), "lowerneck".into()),
            ("head".into(), "upperneck".into()),
        ];
        cmu.extend(sides(
            &[
                ("{s}hipjoint", "root"),
                ("{s}femur", "{s}hipjoint"),
                ("{s}tibia", "{s}femur"),
                ("{s}foot", "{s}tibia"),
                ("{s}toes", "{s}foot"),
                ("{s}clavicle", "thorax"),
                ("{s}humerus", "{s}clavicle"),
                ("{s}radius", "{s}humerus"),
                ("{s}wrist", "{s}radius"),
                ("{s}hand", "{s}wrist"),
                ("{s}fingers", "{s}hand"),
                ("{s}thumb", "{s}hand"),
            ],
            "l",
            "r",
        ));
        check(
            "CMU (ASF)",
            &owned(&cmu),
            &[
                ("root", Hips),
                ("lfemur", LeftUpperLeg),
                ("lwrist", LeftHand),
                ("thorax", UpperChest),
                ("rfoot", RightFoot),
            ],
        );

        // SMPL: `left_foot` is the toes, `left_shoulder` the upper arm.
        let mut smpl = vec![
            ("pelvis".to_owned(), String::new()),
            ("spine1".into(), "pelvis".into()),
            ("spine2".into(), "spine1".into()),
            ("spine3".into(), "spine2".into()),
            ("neck".into(), "spine3".into()),
            ("head".into(), "neck".into()),
        ];
        smpl.extend(sides(
            &[
                ("{s}_hip", "pelvis"),
                ("{s}_knee", "{s}_hip"),
                ("{s}_ankle", "{s}_knee"),
                ("{s}_foot", "{s}_ankle"),
                ("{s}_collar", "spine3"),
                ("{s}_shoulder", "{s}_collar"),
                ("{s}_elbow", "{s}_shoulder"),
                ("{s}_wrist", "{s}_elbow"),
                ("{s}_hand", "{s}_wrist"),
            ],
            "left",
            "right",
        ));
        check(
            "SMPL",
            &owned(&smpl),
            &[
                ("left_foot", LeftToes),
                ("left_ankle", LeftFoot),
                ("right_shoulder", RightUpperArm),
                ("right_collar", RightShoulder),
                ("spine1", Spine),
            ],
        );

        // Unreal (UE5 mannequin): a root on the floor under the pelvis, five spine bones,
        // two neck bones, twist and finger bones.
        let mut unreal = vec![
            ("root".to_owned(), String::new()),
            ("pelvis".into(), "root".into()),
            ("spine_01".into(), "pelvis".into()),
            ("spine_02".into(), "spine_01".into()),
            ("spine_03".into(), "spine_02".into()),
            ("spine_04".into(), "spine_03".into()),
            ("spine_05".into(), "spine_04".into()),
            ("neck_01".into(), "spine_05".into()),
            ("neck_02".into(), "neck_01".into()),
            ("head".into(), "neck_02".into()),
        ];
        unreal.extend(sides(
            &[
                ("thigh_{s}", "pelvis"),
                ("thigh_twist_01_{s}", "thigh_{s}"),
                ("calf_{s}", "thigh_{s}"),
                ("foot_{s}", "calf_{s}"),
                ("ball_{s}", "foot_{s}"),
                ("clavicle_{s}", "spine_05"),
                ("upperarm_{s}", "clavicle_{s}"),
                ("lowerarm_{s}", "upperarm_{s}"),
                ("hand_{s}", "lowerarm_{s}"),
                ("index_01_{s}", "hand_{s}"),
            ],
            "l",
            "r",
        ));
        check(
            "Unreal",
            &owned(&unreal),
            &[
                ("pelvis", Hips),
                ("spine_01", Spine),
                ("spine_05", UpperChest),
                ("neck_01", Neck),
                ("ball_l", LeftToes),
            ],
        );

        // 3ds Max Biped: everything prefixed, a centre-of-mass root above the pelvis.
        let mut biped = vec![
            ("Bip01".to_owned(), String::new()),
            ("Bip01 Pelvis".into(), "Bip01".into()),
            ("Bip01 Spine".into(), "Bip01 Pelvis".into()),
            ("Bip01 Spine1".into(), "Bip01 Spine".into()),
            ("Bip01 Spine2".into(), "Bip01 Spine1".into()),
            ("Bip01 Neck".into(), "Bip01 Spine2".into()),
            ("Bip01 Head".into(), "Bip01 Neck".into()),
        ];
        biped.extend(sides(
            &[
                ("Bip01 {s} Thigh", "Bip01 Pelvis"),
                ("Bip01 {s} Calf", "Bip01 {s} Thigh"),
                ("Bip01 {s} Foot", "Bip01 {s} Calf"),
                ("Bip01 {s} Toe0", "Bip01 {s} Foot"),
                ("Bip01 {s} Clavicle", "Bip01 Neck"),
                ("Bip01 {s} UpperArm", "Bip01 {s} Clavicle"),
                ("Bip01 {s} Forearm", "Bip01 {s} UpperArm"),
                ("Bip01 {s} Hand", "Bip01 {s} Forearm"),
            ],
            "L",
            "R",
        ));
        let bvh = hierarchy(&owned(&biped));
        let found = match_joints(&bvh, &[]);
        assert_eq!(found.convention, "3ds Max Biped");
        // Biped hangs the clavicles off the neck; the neck still drives ours.
        assert_eq!(found.driven[5], Some(Neck));
        assert_eq!(found.driven[7], Some(LeftUpperLeg));

        // Rokoko: four spine bones, thighs and shins.
        let mut rokoko = vec![
            ("Hips".to_owned(), String::new()),
            ("Spine1".into(), "Hips".into()),
            ("Spine2".into(), "Spine1".into()),
            ("Spine3".into(), "Spine2".into()),
            ("Spine4".into(), "Spine3".into()),
            ("Neck".into(), "Spine4".into()),
            ("Head".into(), "Neck".into()),
        ];
        rokoko.extend(sides(
            &[
                ("{s}Thigh", "Hips"),
                ("{s}Shin", "{s}Thigh"),
                ("{s}Foot", "{s}Shin"),
                ("{s}Toe", "{s}Foot"),
                ("{s}ToeEnd", "{s}Toe"),
                ("{s}Shoulder", "Spine4"),
                ("{s}Arm", "{s}Shoulder"),
                ("{s}ForeArm", "{s}Arm"),
                ("{s}Hand", "{s}ForeArm"),
            ],
            "Left",
            "Right",
        ));
        check(
            "Rokoko",
            &owned(&rokoko),
            &[
                ("Spine1", Spine),
                ("Spine3", Chest),
                ("Spine4", UpperChest),
                ("LeftShin", LeftLowerLeg),
                ("RightToe", RightToes),
            ],
        );

        // AMASS's re-exports of CMU (the cmu-dance files).
        let mut amass = vec![
            ("root".to_owned(), String::new()),
            ("lowerback".into(), "root".into()),
            ("upperback".into(), "lowerback".into()),
            ("chest".into(), "upperback".into()),
            ("lowerneck".into(), "chest".into()),
            ("upperneck".into(), "lowerneck".into()),
        ];
        amass.extend(sides(
            &[
                ("{s}hip", "root"),
                ("{s}knee", "{s}hip"),
                ("{s}ankle", "{s}knee"),
                ("{s}toe", "{s}ankle"),
                ("{s}clavicle", "chest"),
                ("{s}shoulder", "{s}clavicle"),
                ("{s}elbow", "{s}shoulder"),
                ("{s}wrist", "{s}elbow"),
            ],
            "l",
            "r",
        ));
        check(
            "AMASS (CMU re-export)",
            &owned(&amass),
            &[
                ("chest", UpperChest),
                ("upperneck", Head),
                ("lshoulder", LeftUpperArm),
                ("rhip", RightUpperLeg),
            ],
        );

        // A convention no table knows: names read by their parts, the spine by the hierarchy.
        let mut other = vec![
            ("CC_Base_Pelvis".to_owned(), String::new()),
            ("CC_Base_Waist".into(), "CC_Base_Pelvis".into()),
            ("CC_Base_Spine01".into(), "CC_Base_Waist".into()),
            ("CC_Base_Spine02".into(), "CC_Base_Spine01".into()),
            ("CC_Base_NeckTwist01".into(), "CC_Base_Spine02".into()),
            ("CC_Base_Head".into(), "CC_Base_NeckTwist01".into()),
        ];
        other.extend(sides(
            &[
                ("CC_Base_{s}_Thigh", "CC_Base_Pelvis"),
                ("CC_Base_{s}_Calf", "CC_Base_{s}_Thigh"),
                ("CC_Base_{s}_Foot", "CC_Base_{s}_Calf"),
                ("CC_Base_{s}_ToeBase", "CC_Base_{s}_Foot"),
                ("CC_Base_{s}_Clavicle", "CC_Base_Spine02"),
                ("CC_Base_{s}_Upperarm", "CC_Base_{s}_Clavicle"),
                ("CC_Base_{s}_Forearm", "CC_Base_{s}_Upperarm"),
                ("CC_Base_{s}_Hand", "CC_Base_{s}_Forearm"),
            ],
            "L",
            "R",
        ));
        let bvh = hierarchy(&owned(&other));
        let found = match_joints(&bvh, &[]);
        assert_eq!(found.convention, "names by their parts");
        let driver =
            |name: &str| found.driven[bvh.joints.iter().position(|j| j.name == name).unwrap()];
        assert_eq!(driver("CC_Base_Pelvis"), Some(Hips));
        assert_eq!(driver("CC_Base_Waist"), Some(Spine));
        assert_eq!(driver("CC_Base_Spine01"), Some(Chest));
        assert_eq!(driver("CC_Base_Spine02"), Some(UpperChest));
        assert_eq!(driver("CC_Base_NeckTwist01"), Some(Neck));
        assert_eq!(driver("CC_Base_L_Thigh"), Some(LeftUpperLeg));
        assert_eq!(driver("CC_Base_R_ToeBase"), Some(RightToes));
        assert_eq!(driver("CC_Base_R_Upperarm"), Some(RightUpperArm));
    }
}
