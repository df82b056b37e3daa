//! The LU-parameterised invertible linear map of a flow step: W = P · L · U with P a fixed
//! permutation, L unit lower-triangular and U upper-triangular with diagonal exp(log_s), so
//! log|det W| = Σ log_s exactly and W is invertible by construction.

/// W as a row-major `d × d` matrix (f64: its inverse is taken from it).
pub fn weight(perm: &[usize], lower: &[f32], upper: &[f32], log_s: &[f32]) -> Vec<f64> {
    let d = perm.len();
    // L · U with L's unit diagonal and U's exp(log_s) diagonal made explicit.
    let mut lu = vec![0.0f64; d * d];
    for i in 0..d {
        for j in 0..d {
            let mut s = 0.0;
            for k in 0..=i.min(j) {
                let l = if k == i { 1.0 } else { lower[i * d + k] as f64 };
                let u = if k == j {
                    (log_s[j] as f64).exp()
                } else {
                    upper[k * d + j] as f64
                };
                s += l * u;
            }
            lu[i * d + j] = s;
        }
    }
    // (P v)_i = v_{perm[i]}: row i of P·LU is row perm[i] of LU.
    let mut w = vec![0.0; d * d];
    for i in 0..d {
        w[i * d..(i + 1) * d].copy_from_slice(&lu[perm[i] * d..(perm[i] + 1) * d]);
    }
    w
}

/// The inverse of a row-major `d × d` matrix, as f32 (None if numerically singular).
pub fn inverse(w: &[f64], d: usize) -> Option<Vec<f32>> {
    let m = nalgebra::DMatrix::from_row_slice(d, d, w);
    let inv = m.try_inverse()?;
    let mut out = vec![0.0f32; d * d];
    for i in 0..d {
        for j in 0..d {
            out[i * d + j] = inv[(i, j)] as f32;
        }
    }
    out.iter().all(|v| v.is_finite()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn determinant_is_exp_sum_log_s() {
        let perm = [2, 0, 1];
        let lower = [0.0, 0.0, 0.0, 0.5, 0.0, 0.0, -0.3, 0.2, 0.0];
        let upper = [0.0, 0.4, 0.1, 0.0, 0.0, -0.7, 0.0, 0.0, 0.0];
        let log_s = [0.1, -0.2, 0.3];
        let w = weight(&perm, &lower, &upper, &log_s);
        let det = nalgebra::DMatrix::from_row_slice(3, 3, &w).determinant();
        // An odd/even permutation flips the sign; the magnitude is exp(Σ log_s).
        assert!((det.abs() - (0.2f64).exp()).abs() < 1e-6, "det {det}");
        let inv = inverse(&w, 3).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let s: f64 = (0..3).map(|k| w[i * 3 + k] * inv[k * 3 + j] as f64).sum();
                assert!((s - if i == j { 1.0 } else { 0.0 }).abs() < 1e-6);
            }
        }
    }
}
