//! Rotation representations and helpers: exponential map, 6D (Zhou et al. 2019), swing-twist,
//! shortest arc.
//!
//! Every function here accepts any input, including zero, non-unit, huge, infinite and NaN
//! values (network outputs and imported files), and returns a finite result: degenerate input
//! falls back to the identity or to the rotation closest to it. Quaternions are glam's `Quat`
//! (`x, y, z, w`); inputs are normalised before use, outputs are unit.

use glam::{DQuat, DVec3, Mat3, Quat, Vec3};

/// Below this squared norm a vector or quaternion is treated as zero.
const TINY_SQ: f32 = 1e-24;

/// `q` normalised with `w ≥ 0` (the shortest-arc representative), identity if degenerate.
#[inline]
pub fn canonical(q: Quat) -> Quat {
    let q = normalize_or_identity(q);
    if q.w < 0.0 { -q } else { q }
}

/// `q` normalised, or the identity if it is zero or not finite.
#[inline]
pub fn normalize_or_identity(q: Quat) -> Quat {
    if !q.is_finite() {
        return Quat::IDENTITY;
    }
    // Scaling by the largest component first keeps the squared norm of huge or tiny input
    // representable.
    let v = glam::Vec4::from(q);
    let m = v.abs().max_element();
    if m == 0.0 {
        return Quat::IDENTITY;
    }
    let v = v / m;
    let n2 = v.length_squared();
    Quat::from_vec4(v / n2.sqrt())
}

/// Exponential map of `q`: rotation axis times angle in radians, angle in `[0, π]`.
///
/// `q` and `−q` give the same result (the shortest arc is taken); the identity gives zero.
pub fn quat_to_expmap(q: Quat) -> Vec3 {
    let q = canonical(q);
    let v = q.xyz();
    let s = v.length();
    // atan2 keeps full precision both near 0 (w ≈ 1) and near π (w ≈ 0), where acos/asin lose it.
    let scale = if s < 1e-6 {
        // angle / s → 2 / w; the next term is O(s²), below f32 resolution here.
        2.0 / q.w
    } else {
        2.0 * s.atan2(q.w) / s
    };
    v * scale
}

/// The rotation by `|v|` radians about `v`; zero or non-finite `v` gives the identity.
pub fn expmap_to_quat(v: Vec3) -> Quat {
    if !v.is_finite() {
        return Quat::IDENTITY;
    }
    let angle = v.length();
    if !angle.is_finite() {
        // Finite components can overflow the norm; such an angle has no meaningful value mod 2π.
        return Quat::IDENTITY;
    }
    let half = 0.5 * angle;
    // sin(θ/2)/θ → 1/2 − θ²/48 near 0, where the division would lose precision or divide by 0.
    let k = if angle < 1e-4 {
        0.5 - angle * angle / 48.0
    } else {
        half.sin() / angle
    };
    normalize_or_identity(Quat::from_xyzw(v.x * k, v.y * k, v.z * k, half.cos()))
}

/// 6D representation of `q`: the first two columns of its rotation matrix, `[c0.x, c0.y, c0.z,
/// c1.x, c1.y, c1.z]` (the images of +X and +Y).
pub fn quat_to_6d(q: Quat) -> [f32; 6] {
    let q = normalize_or_identity(q);
    let c0 = q * Vec3::X;
    let c1 = q * Vec3::Y;
    [c0.x, c0.y, c0.z, c1.x, c1.y, c1.z]
}

/// The rotation whose first two matrix columns are closest to `d` (Gram–Schmidt), never NaN.
///
/// Non-finite components count as 0. If the first column vanishes, the second alone sets the Y
/// axis; if both vanish, the identity. A second column parallel to the first is replaced by the
/// direction closest to +Y (or +Z) perpendicular to it, so nearly degenerate input gives a
/// rotation close to the identity's axes rather than an arbitrary one.
pub fn sixd_to_quat(d: [f32; 6]) -> Quat {
    let d = d.map(|x| if x.is_finite() { x } else { 0.0 });
    // A common scale does not change the result; dividing by the largest component keeps every
    // squared norm below in range however large or small the input.
    let m = d.iter().fold(0.0f32, |m, x| m.max(x.abs()));
    if m == 0.0 {
        return Quat::IDENTITY;
    }
    let a = Vec3::new(d[0], d[1], d[2]) / m;
    let b = Vec3::new(d[3], d[4], d[5]) / m;

    let (x, y) = match (a.try_normalize(), b.try_normalize()) {
        (Some(x), _) => {
            let y = perpendicular_towards(x, b)
                .or_else(|| perpendicular_towards(x, Vec3::Y))
                .or_else(|| perpendicular_towards(x, Vec3::Z))
                .unwrap_or_else(|| x.any_orthonormal_vector());
            (x, y)
        }
        (None, Some(y)) => {
            let x = perpendicular_towards(y, Vec3::X)
                .or_else(|| perpendicular_towards(y, Vec3::Z))
                .unwrap_or_else(|| y.any_orthonormal_vector());
            (x, y)
        }
        (None, None) => return Quat::IDENTITY,
    };
    let z = x.cross(y);
    normalize_or_identity(Quat::from_mat3(&Mat3::from_cols(x, y, z)))
}

/// The unit part of `v` perpendicular to the unit vector `n`, if it is not (nearly) zero.
#[inline]
fn perpendicular_towards(n: Vec3, v: Vec3) -> Option<Vec3> {
    let p = v - n * n.dot(v);
    if p.length_squared() > 1e-12 * v.length_squared().max(TINY_SQ) {
        p.try_normalize()
    } else {
        None
    }
}

/// Splits `q` into `(swing, twist)` with `q = swing * twist`, `twist` about `axis` and `swing`
/// about an axis perpendicular to it.
///
/// The same `twist` also satisfies `q = twist * swing'` for `swing' = twist⁻¹ * q`. When the
/// twist is undefined (a half turn about an axis perpendicular to `axis`) it is the identity; a
/// zero or non-finite `axis` gives `(q, identity)`.
pub fn swing_twist(q: Quat, axis: Vec3) -> (Quat, Quat) {
    let q = normalize_or_identity(q);
    let Some(axis) = unit(axis) else {
        return (q, Quat::IDENTITY);
    };
    let p = axis * axis.dot(q.xyz());
    let t = Quat::from_xyzw(p.x, p.y, p.z, q.w);
    let twist = if t.length_squared() > 1e-12 {
        t.normalize()
    } else {
        Quat::IDENTITY
    };
    (q * twist.conjugate(), twist)
}

/// The signed twist angle of `q` about `axis`, radians in `(−π, π]`.
pub fn twist_angle(q: Quat, axis: Vec3) -> f32 {
    let (_, twist) = swing_twist(q, axis);
    let Some(axis) = unit(axis) else {
        return 0.0;
    };
    let s = twist.xyz().dot(axis);
    let angle = 2.0 * s.atan2(twist.w);
    wrap_angle(angle)
}

/// `angle` wrapped into `[−π, π)`; non-finite gives 0.
#[inline]
pub fn wrap_angle(angle: f32) -> f32 {
    use std::f32::consts::{PI, TAU};
    if !angle.is_finite() {
        return 0.0;
    }
    let a = (angle + PI).rem_euclid(TAU) - PI;
    // rem_euclid can round up to exactly TAU.
    if a >= PI { a - TAU } else { a }
}

/// The shortest rotation taking the direction of `a` to the direction of `b`.
///
/// Antiparallel vectors give a half turn about an axis perpendicular to `a` (the one closest to
/// +Y, then +Z, so the choice is stable); a zero or non-finite vector gives the identity.
pub fn rotation_between(a: Vec3, b: Vec3) -> Quat {
    let (Some(a), Some(b)) = (unit_f64(a), unit_f64(b)) else {
        return Quat::IDENTITY;
    };
    // Half-way formula, q = (a × h, a · h) with h the unit bisector, in f64: near the
    // antiparallel case the rotation axis hangs on the tiny a + b, which f32 normalisation
    // errors (~1e-7) would swamp, and 1 + a·b or a × b would cancel catastrophically.
    let h = a + b;
    if h.length_squared() > 1e-24 {
        let h = h.normalize();
        let c = a.cross(h);
        let q = DQuat::from_xyzw(c.x, c.y, c.z, a.dot(h)).normalize();
        return normalize_or_identity(q.as_quat());
    }
    let a = a.as_vec3();
    let axis = perpendicular_towards(a, Vec3::Y)
        .or_else(|| perpendicular_towards(a, Vec3::Z))
        .unwrap_or_else(|| a.any_orthonormal_vector());
    Quat::from_xyzw(axis.x, axis.y, axis.z, 0.0)
}

/// `v` normalised, robust to huge and tiny magnitudes; `None` if zero or not finite.
#[inline]
fn unit(v: Vec3) -> Option<Vec3> {
    if !v.is_finite() {
        return None;
    }
    let m = v.abs().max_element();
    if m == 0.0 {
        return None;
    }
    (v / m).try_normalize()
}

/// `v` normalised in f64; `None` if zero or not finite.
#[inline]
fn unit_f64(v: Vec3) -> Option<DVec3> {
    if !v.is_finite() {
        return None;
    }
    // Every finite f32 vector's squared norm is representable in f64.
    v.as_dvec3().try_normalize()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f32::consts::{FRAC_PI_2, PI};

    const EPS: f32 = 1e-5;

    pub(crate) fn same_rotation(a: Quat, b: Quat, eps: f32) -> bool {
        let b = if a.dot(b) < 0.0 { -b } else { b };
        (glam::Vec4::from(a) - glam::Vec4::from(b))
            .abs()
            .max_element()
            <= eps
    }

    fn finite_unit(q: Quat) -> bool {
        q.is_finite() && (q.length() - 1.0).abs() < 1e-5
    }

    fn unit_quat() -> impl Strategy<Value = Quat> {
        prop::array::uniform4(-1.0f32..1.0)
            .prop_filter("non-degenerate", |a| {
                a.iter().map(|x| x * x).sum::<f32>() > 1e-3
            })
            .prop_map(|a| Quat::from_array(a).normalize())
    }

    fn unit_vec() -> impl Strategy<Value = Vec3> {
        prop::array::uniform3(-1.0f32..1.0)
            .prop_filter("non-degenerate", |a| {
                a.iter().map(|x| x * x).sum::<f32>() > 1e-3
            })
            .prop_map(|a| Vec3::from_array(a).normalize())
    }

    /// Rotations with angles near 0 and near π as well as anywhere.
    fn any_rotation() -> impl Strategy<Value = Quat> {
        prop_oneof![
            unit_quat(),
            (unit_vec(), 0.0f32..1e-3).prop_map(|(a, t)| Quat::from_axis_angle(a, t)),
            (unit_vec(), 0.0f32..1e-3).prop_map(|(a, t)| Quat::from_axis_angle(a, PI - t)),
        ]
    }

    #[test]
    fn known_rotations() {
        let s = std::f32::consts::FRAC_1_SQRT_2;
        for (axis, q) in [
            (Vec3::X, Quat::from_xyzw(s, 0.0, 0.0, s)),
            (Vec3::Y, Quat::from_xyzw(0.0, s, 0.0, s)),
            (Vec3::Z, Quat::from_xyzw(0.0, 0.0, s, s)),
        ] {
            let e = quat_to_expmap(q);
            assert!(e.abs_diff_eq(axis * FRAC_PI_2, 1e-6), "{e}");
            assert!(same_rotation(expmap_to_quat(axis * FRAC_PI_2), q, 1e-6));
            assert!(same_rotation(sixd_to_quat(quat_to_6d(q)), q, 1e-6));
        }
        // 90° about X: X stays, Y goes to Z.
        let d = quat_to_6d(Quat::from_rotation_x(FRAC_PI_2));
        let expected = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        assert!(
            d.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-6),
            "{d:?}"
        );
        // 90° about Y: X goes to −Z, Y stays.
        let d = quat_to_6d(Quat::from_rotation_y(FRAC_PI_2));
        let expected = [0.0, 0.0, -1.0, 0.0, 1.0, 0.0];
        assert!(
            d.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-6),
            "{d:?}"
        );
        // 90° about Z: X goes to Y, Y to −X.
        let d = quat_to_6d(Quat::from_rotation_z(FRAC_PI_2));
        let expected = [0.0, 1.0, 0.0, -1.0, 0.0, 0.0];
        assert!(
            d.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-6),
            "{d:?}"
        );

        assert_eq!(quat_to_expmap(Quat::IDENTITY), Vec3::ZERO);
        assert_eq!(expmap_to_quat(Vec3::ZERO), Quat::IDENTITY);
        assert_eq!(quat_to_6d(Quat::IDENTITY), [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        // Shortest arc: 270° about +Y is 90° about −Y.
        let e = quat_to_expmap(Quat::from_rotation_y(1.5 * PI));
        assert!(e.abs_diff_eq(Vec3::new(0.0, -FRAC_PI_2, 0.0), 1e-5), "{e}");
        let e = quat_to_expmap(-Quat::from_rotation_x(0.3));
        assert!(e.abs_diff_eq(Vec3::new(0.3, 0.0, 0.0), 1e-6), "{e}");
    }

    #[test]
    fn degenerate_6d() {
        assert_eq!(sixd_to_quat([0.0; 6]), Quat::IDENTITY);
        assert_eq!(sixd_to_quat([f32::NAN; 6]), Quat::IDENTITY);
        // Only the second column: it sets Y, X is the closest to +X perpendicular to it.
        let q = sixd_to_quat([0.0, 0.0, 0.0, 0.0, 2.0, 0.0]);
        assert!(same_rotation(q, Quat::IDENTITY, 1e-6));
        // Parallel columns: Y falls back to the closest to +Y.
        let q = sixd_to_quat([3.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
        assert!(same_rotation(q, Quat::IDENTITY, 1e-6));
        // First column along Y with the second parallel: Y falls back to +Z's direction.
        let q = sixd_to_quat([0.0, 1.0, 0.0, 0.0, -1.0, 0.0]);
        assert!(finite_unit(q));
        assert!((q * Vec3::X).abs_diff_eq(Vec3::Y, 1e-6));
        // Non-orthogonal, unnormalised columns: Gram–Schmidt keeps the first column's direction.
        let q = sixd_to_quat([2.0, 0.0, 0.0, 1.0, 1.0, 0.0]);
        assert!(same_rotation(q, Quat::IDENTITY, 1e-6));
        let q = sixd_to_quat([f32::MAX, f32::MAX, 0.0, f32::MIN_POSITIVE, 0.0, 1e-40]);
        assert!(finite_unit(q));
    }

    #[test]
    fn degenerate_helpers() {
        assert_eq!(rotation_between(Vec3::ZERO, Vec3::X), Quat::IDENTITY);
        assert_eq!(rotation_between(Vec3::X, Vec3::NAN), Quat::IDENTITY);
        for a in [Vec3::X, Vec3::Y, -Vec3::Z, Vec3::new(1.0, 2.0, 3.0)] {
            let q = rotation_between(a, -a * 3.0);
            assert!(finite_unit(q));
            assert!((q * a.normalize()).abs_diff_eq(-a.normalize(), 1e-6), "{a}");
            assert!(q.w.abs() < 1e-6, "a half turn");
        }
        // Nearly antiparallel stays accurate.
        let a = Vec3::X;
        let b = Vec3::new(-1.0, 1e-4, 0.0);
        let q = rotation_between(a, b);
        assert!((q * a).abs_diff_eq(b.normalize(), 1e-6), "{}", q * a);
        let (swing, twist) = swing_twist(Quat::from_rotation_x(PI), Vec3::Y);
        assert!(finite_unit(swing) && twist == Quat::IDENTITY);
        let q = Quat::from_rotation_z(0.4);
        for axis in [Vec3::ZERO, Vec3::NAN] {
            let (swing, twist) = swing_twist(q, axis);
            assert!(same_rotation(swing, q, 1e-7) && twist == Quat::IDENTITY);
        }
        assert!((twist_angle(Quat::from_rotation_y(-2.0), Vec3::Y) + 2.0).abs() < 1e-6);
        assert!((twist_angle(Quat::from_rotation_y(3.0), -Vec3::Y) + 3.0).abs() < 1e-6);
        assert_eq!(wrap_angle(PI), -PI);
        assert!((wrap_angle(3.0 * PI + 0.5) - (-PI + 0.5)).abs() < 1e-5);
        assert_eq!(wrap_angle(f32::NAN), 0.0);
        assert_eq!(
            canonical(Quat::from_xyzw(0.0, 0.0, 0.0, 0.0)),
            Quat::IDENTITY
        );
        assert_eq!(expmap_to_quat(Vec3::INFINITY), Quat::IDENTITY);
        assert!(finite_unit(expmap_to_quat(Vec3::splat(f32::MAX))));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        #[test]
        fn expmap_round_trip(q in any_rotation()) {
            let q2 = expmap_to_quat(quat_to_expmap(q));
            prop_assert!(same_rotation(q, q2, EPS), "{q} -> {q2}");
            prop_assert!(quat_to_expmap(q).length() <= PI + 1e-6);
        }

        #[test]
        fn expmap_round_trip_from_vector(axis in unit_vec(), angle in 0.0f32..(PI - 1e-3)) {
            let v = axis * angle;
            let v2 = quat_to_expmap(expmap_to_quat(v));
            prop_assert!(v.abs_diff_eq(v2, EPS), "{v} -> {v2}");
            // Small angles keep their relative precision.
            let tiny = axis * (angle * 1e-6);
            let tiny2 = quat_to_expmap(expmap_to_quat(tiny));
            prop_assert!(tiny.abs_diff_eq(tiny2, 1e-11), "{tiny} -> {tiny2}");
        }

        #[test]
        fn sixd_round_trip(q in any_rotation()) {
            let q2 = sixd_to_quat(quat_to_6d(q));
            prop_assert!(same_rotation(q, q2, EPS), "{q} -> {q2}");
            let d = quat_to_6d(q);
            let d2 = quat_to_6d(q2);
            prop_assert!(d.iter().zip(d2).all(|(a, b)| (a - b).abs() <= EPS));
        }

        #[test]
        fn sixd_is_gram_schmidt(q in unit_quat(), s in 0.1f32..10.0, skew in -0.9f32..0.9) {
            // Scaling the first column and shearing the second along it is undone exactly.
            let c0 = q * Vec3::X;
            let c1 = q * Vec3::Y;
            let a = c0 * s;
            let b = (c1 + c0 * skew) * (s * 0.5);
            let q2 = sixd_to_quat([a.x, a.y, a.z, b.x, b.y, b.z]);
            prop_assert!(same_rotation(q, q2, EPS));
        }

        #[test]
        fn degenerate_input_is_never_nan(
            d in prop::array::uniform6(prop_oneof![
                Just(0.0f32), Just(f32::NAN), Just(f32::INFINITY), Just(-f32::INFINITY),
                Just(f32::MAX), Just(1e-40f32), Just(1.0f32), Just(-1.0f32),
                proptest::num::f32::ANY,
            ]),
        ) {
            prop_assert!(finite_unit(sixd_to_quat(d)));
            let v = Vec3::new(d[0], d[1], d[2]);
            let w = Vec3::new(d[3], d[4], d[5]);
            let q = Quat::from_xyzw(d[0], d[1], d[2], d[3]);
            prop_assert!(finite_unit(expmap_to_quat(v)));
            prop_assert!(quat_to_expmap(q).is_finite());
            prop_assert!(quat_to_6d(q).iter().all(|x| x.is_finite()));
            prop_assert!(finite_unit(rotation_between(v, w)));
            let (swing, twist) = swing_twist(q, v);
            prop_assert!(finite_unit(swing) && finite_unit(twist));
            prop_assert!(twist_angle(q, v).is_finite());
            prop_assert!(finite_unit(canonical(q)));
        }

        #[test]
        fn rotation_between_is_shortest_arc(a in unit_vec(), b in unit_vec(), sa in 0.01f32..100.0, sb in 0.01f32..100.0) {
            let q = rotation_between(a * sa, b * sb);
            prop_assert!(finite_unit(q));
            prop_assert!((q * a).abs_diff_eq(b, EPS), "{} vs {b}", q * a);
            // The shortest arc turns about a × b by the angle between them.
            let angle = a.dot(b).clamp(-1.0, 1.0).acos();
            prop_assert!((quat_to_expmap(q).length() - angle).abs() < 1e-3);
        }

        #[test]
        fn swing_twist_decomposes(q in unit_quat(), axis in unit_vec()) {
            let (swing, twist) = swing_twist(q, axis);
            prop_assert!(same_rotation(swing * twist, q, EPS));
            prop_assert!(twist.xyz().cross(axis).length() < EPS, "twist about the axis");
            prop_assert!(swing.xyz().dot(axis).abs() < EPS, "swing perpendicular to the axis");
            let other = twist.conjugate() * q;
            prop_assert!(other.xyz().dot(axis).abs() < EPS, "also q = twist * swing'");
            let angle = twist_angle(q, axis);
            prop_assert!(same_rotation(Quat::from_axis_angle(axis, angle), twist, EPS));
        }
    }
}
