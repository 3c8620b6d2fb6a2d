//! Small dense matrices of fixed size for the stage-wise algebra of the NMPC and
//! the MHE (5 × 5, 4 × 4, ...): plain arrays, no allocation, loops the compiler
//! unrolls.

/// An `R × C` matrix, row-major.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mat<const R: usize, const C: usize>(pub [[f64; C]; R]);

impl<const R: usize, const C: usize> Default for Mat<R, C> {
    fn default() -> Self {
        Mat([[0.0; C]; R])
    }
}

impl<const R: usize, const C: usize> Mat<R, C> {
    /// The zero matrix.
    pub fn zero() -> Self {
        Self::default()
    }

    /// `self · other`.
    pub fn mul<const K: usize>(&self, other: &Mat<C, K>) -> Mat<R, K> {
        let mut out = Mat::<R, K>::zero();
        for r in 0..R {
            for k in 0..K {
                let mut acc = 0.0;
                for c in 0..C {
                    acc += self.0[r][c] * other.0[c][k];
                }
                out.0[r][k] = acc;
            }
        }
        out
    }

    /// `selfᵀ · other`.
    pub fn tmul<const K: usize>(&self, other: &Mat<R, K>) -> Mat<C, K> {
        let mut out = Mat::<C, K>::zero();
        for c in 0..C {
            for k in 0..K {
                let mut acc = 0.0;
                for r in 0..R {
                    acc += self.0[r][c] * other.0[r][k];
                }
                out.0[c][k] = acc;
            }
        }
        out
    }

    /// `self + other`.
    pub fn add(&self, other: &Self) -> Self {
        let mut out = *self;
        for r in 0..R {
            for c in 0..C {
                out.0[r][c] += other.0[r][c];
            }
        }
        out
    }

    /// Row `r` times `v` (`(self · v)[r]`).
    pub fn row_dot(&self, r: usize, v: &[f64; C]) -> f64 {
        self.0[r].iter().zip(v).map(|(a, b)| a * b).sum()
    }

    /// Column `c` times `v` (`(selfᵀ · v)[c]`).
    pub fn col_dot(&self, c: usize, v: &[f64; R]) -> f64 {
        (0..R).map(|r| self.0[r][c] * v[r]).sum()
    }
}

impl<const N: usize> Mat<N, N> {
    /// A diagonal matrix.
    pub fn diag(d: [f64; N]) -> Self {
        let mut m = Self::zero();
        for i in 0..N {
            m.0[i][i] = d[i];
        }
        m
    }

    /// `(self + selfᵀ) / 2`.
    pub fn symmetrised(&self) -> Self {
        let mut m = *self;
        for r in 0..N {
            for c in 0..r {
                let v = 0.5 * (self.0[r][c] + self.0[c][r]);
                m.0[r][c] = v;
                m.0[c][r] = v;
            }
        }
        m
    }
}

/// The Cholesky factor `L` (lower) of a symmetric positive definite matrix, or
/// `None` if a pivot is not positive (or not finite).
pub fn cholesky<const N: usize>(a: &Mat<N, N>) -> Option<Mat<N, N>> {
    let mut l = Mat::<N, N>::zero();
    for j in 0..N {
        let mut d = a.0[j][j];
        for k in 0..j {
            d -= l.0[j][k] * l.0[j][k];
        }
        if !(d.is_finite() && d > 0.0) {
            return None;
        }
        let djj = d.sqrt();
        l.0[j][j] = djj;
        for i in j + 1..N {
            let mut s = a.0[i][j];
            for k in 0..j {
                s -= l.0[i][k] * l.0[j][k];
            }
            l.0[i][j] = s / djj;
        }
    }
    Some(l)
}

/// Solve `L Lᵀ x = b` given the Cholesky factor `L`.
pub fn cholesky_solve<const N: usize>(l: &Mat<N, N>, b: &[f64; N]) -> [f64; N] {
    let mut y = *b;
    for i in 0..N {
        for k in 0..i {
            y[i] -= l.0[i][k] * y[k];
        }
        y[i] /= l.0[i][i];
    }
    for i in (0..N).rev() {
        for k in i + 1..N {
            y[i] -= l.0[k][i] * y[k];
        }
        y[i] /= l.0[i][i];
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_and_refuses_indefinite_matrices() {
        let a = Mat([[4.0, 2.0, 0.6], [2.0, 5.0, 1.0], [0.6, 1.0, 3.0]]);
        let l = cholesky(&a).unwrap();
        let x = cholesky_solve(&l, &[1.0, 2.0, 3.0]);
        for r in 0..3 {
            assert!((a.row_dot(r, &x) - [1.0, 2.0, 3.0][r]).abs() < 1e-12);
        }
        assert!(cholesky(&Mat([[1.0, 2.0], [2.0, 1.0]])).is_none());
        assert!(cholesky(&Mat([[f64::NAN]])).is_none());
    }

    #[test]
    fn products_and_transposes() {
        let a = Mat([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]);
        let b = Mat([[1.0, 0.0, 2.0], [0.0, 1.0, 1.0]]);
        assert_eq!(
            a.mul(&b).0,
            [[1.0, 2.0, 4.0], [3.0, 4.0, 10.0], [5.0, 6.0, 16.0]]
        );
        assert_eq!(a.tmul(&a).0, [[35.0, 44.0], [44.0, 56.0]]);
        assert_eq!(a.col_dot(1, &[1.0, 1.0, 1.0]), 12.0);
    }
}
