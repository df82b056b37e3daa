//! Unity's `HumanBodyBones` names, the vocabulary every layout names bones in.

/// Every `HumanBodyBones` value except `LastBone`, in Unity's enum order.
pub const HUMAN_BODY_BONES: [&str; 55] = [
    "Hips",
    "LeftUpperLeg",
    "RightUpperLeg",
    "LeftLowerLeg",
    "RightLowerLeg",
    "LeftFoot",
    "RightFoot",
    "Spine",
    "Chest",
    "Neck",
    "Head",
    "LeftShoulder",
    "RightShoulder",
    "LeftUpperArm",
    "RightUpperArm",
    "LeftLowerArm",
    "RightLowerArm",
    "LeftHand",
    "RightHand",
    "LeftToes",
    "RightToes",
    "LeftEye",
    "RightEye",
    "Jaw",
    "LeftThumbProximal",
    "LeftThumbIntermediate",
    "LeftThumbDistal",
    "LeftIndexProximal",
    "LeftIndexIntermediate",
    "LeftIndexDistal",
    "LeftMiddleProximal",
    "LeftMiddleIntermediate",
    "LeftMiddleDistal",
    "LeftRingProximal",
    "LeftRingIntermediate",
    "LeftRingDistal",
    "LeftLittleProximal",
    "LeftLittleIntermediate",
    "LeftLittleDistal",
    "RightThumbProximal",
    "RightThumbIntermediate",
    "RightThumbDistal",
    "RightIndexProximal",
    "RightIndexIntermediate",
    "RightIndexDistal",
    "RightMiddleProximal",
    "RightMiddleIntermediate",
    "RightMiddleDistal",
    "RightRingProximal",
    "RightRingIntermediate",
    "RightRingDistal",
    "RightLittleProximal",
    "RightLittleIntermediate",
    "RightLittleDistal",
    "UpperChest",
];

/// The `HumanBodyBones` name `name` means, spelled as Unity spells it (ASCII case-insensitive,
/// surrounding space ignored, as hand-written configs are not always careful), or `None`.
pub fn canonical_bone(name: &str) -> Option<&'static str> {
    let name = name.trim();
    HUMAN_BODY_BONES
        .iter()
        .find(|b| b.eq_ignore_ascii_case(name))
        .copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_bones_whatever_their_case() {
        assert_eq!(canonical_bone("Hips"), Some("Hips"));
        assert_eq!(canonical_bone(" leftlowerarm "), Some("LeftLowerArm"));
        assert_eq!(canonical_bone("UPPERCHEST"), Some("UpperChest"));
        assert_eq!(canonical_bone("Tail"), None);
        assert_eq!(canonical_bone(""), None);
        let mut names = HUMAN_BODY_BONES.to_vec();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), HUMAN_BODY_BONES.len());
    }
}
