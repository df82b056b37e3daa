//! The one place that decides what replaces a non-finite value before it goes on the wire.
//!
//! Receivers (TouchDesigner, VSeeFace, VRChat) do not survive NaN gracefully: a NaN position
//! poisons a smoothing filter forever. So a value that is not finite is replaced by the neutral
//! value of its kind: a scalar by 0, a vector with any non-finite component by the zero vector,
//! a quaternion with any non-finite component (or of zero length) by the identity. Quaternions
//! are also renormalised, since receivers treat them as unit rotations.

use glam::{Quat, Vec3};

/// A finite scalar, 0 in place of NaN or ±∞.
pub fn scalar(x: f32) -> f32 {
    if x.is_finite() { x } else { 0.0 }
}

/// A finite f64 narrowed to f32, 0 in place of NaN, ±∞ or values beyond f32's range.
pub fn scalar64(x: f64) -> f32 {
    scalar(x as f32)
}

/// A finite vector, the zero vector when any component is not finite.
pub fn vec3(v: Vec3) -> Vec3 {
    if v.is_finite() { v } else { Vec3::ZERO }
}

/// A finite unit quaternion, the identity when any component is not finite or it has no length.
pub fn quat(q: Quat) -> Quat {
    if !q.is_finite() {
        return Quat::IDENTITY;
    }
    let len2 = q.length_squared();
    if !len2.is_finite() || len2 <= 1e-12 {
        return Quat::IDENTITY;
    }
    q / len2.sqrt()
}

/// Whether every value is finite (for counting replacements).
pub fn is_finite_pose(v: Vec3, q: Quat) -> bool {
    v.is_finite() && q.is_finite()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_non_finite_values_with_neutral_ones() {
        assert_eq!(scalar(f32::NAN), 0.0);
        assert_eq!(scalar(f32::INFINITY), 0.0);
        assert_eq!(scalar(1.5), 1.5);
        assert_eq!(scalar64(1e300), 0.0);
        assert_eq!(scalar64(2.25), 2.25);
        assert_eq!(vec3(Vec3::new(1.0, f32::NAN, 2.0)), Vec3::ZERO);
        assert_eq!(vec3(Vec3::new(1.0, 3.0, 2.0)), Vec3::new(1.0, 3.0, 2.0));
        assert_eq!(
            quat(Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0)),
            Quat::IDENTITY
        );
        assert_eq!(quat(Quat::from_xyzw(0.0, 0.0, 0.0, 0.0)), Quat::IDENTITY);
        let q = quat(Quat::from_xyzw(0.0, 0.0, 0.0, 2.0));
        assert_eq!(q, Quat::IDENTITY);
        let q = quat(Quat::from_xyzw(0.0, 3.0, 0.0, 4.0));
        assert!((q.y - 0.6).abs() < 1e-6 && (q.w - 0.8).abs() < 1e-6);
    }
}
