//! A sparse matrix whose pattern is fixed once, then refilled in place every step:
//! what Clarabel's `update_P`/`update_A` need (same sparsity, explicit zeros kept).

use clarabel::algebra::CscMatrix;

/// Entries are declared once as `(row, column)` in any order; [`Pattern::csc`]
/// builds the compressed-column matrix and [`Pattern::scatter`] writes new values,
/// given in declaration order, into its `nzval` without allocating.
#[derive(Clone, Debug)]
pub struct Pattern {
    rows: usize,
    cols: usize,
    entries: Vec<(usize, usize)>,
    /// For each declared entry, its index in `nzval`.
    slot: Vec<usize>,
    colptr: Vec<usize>,
    rowval: Vec<usize>,
}

impl Pattern {
    /// An empty `rows × cols` pattern.
    pub fn new(rows: usize, cols: usize) -> Pattern {
        Pattern {
            rows,
            cols,
            entries: Vec::new(),
            slot: Vec::new(),
            colptr: Vec::new(),
            rowval: Vec::new(),
        }
    }

    /// Declare entry `(row, col)`; returns its index in declaration order.
    /// Declaring the same position twice makes the two values add up.
    pub fn push(&mut self, row: usize, col: usize) -> usize {
        debug_assert!(row < self.rows && col < self.cols, "({row}, {col}) outside");
        self.entries.push((row, col));
        self.entries.len() - 1
    }

    /// Number of declared entries.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether nothing is declared.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Fix the pattern: compute the CSC structure and where each entry goes.
    pub fn compile(&mut self) {
        let mut order: Vec<usize> = (0..self.entries.len()).collect();
        order.sort_by_key(|&i| (self.entries[i].1, self.entries[i].0));
        self.slot = vec![0; self.entries.len()];
        self.colptr = vec![0; self.cols + 1];
        self.rowval.clear();
        let mut last: Option<(usize, usize)> = None;
        for &i in &order {
            let (r, c) = self.entries[i];
            if last != Some((r, c)) {
                self.rowval.push(r);
                self.colptr[c + 1] += 1;
                last = Some((r, c));
            }
            self.slot[i] = self.rowval.len() - 1;
        }
        for c in 0..self.cols {
            self.colptr[c + 1] += self.colptr[c];
        }
    }

    /// Number of stored values (positions), after [`Pattern::compile`].
    pub fn nnz(&self) -> usize {
        self.rowval.len()
    }

    /// Write `values` (one per declared entry, in declaration order) into `nzval`.
    pub fn scatter(&self, values: &[f64], nzval: &mut [f64]) {
        nzval.iter_mut().for_each(|v| *v = 0.0);
        for (&slot, &v) in self.slot.iter().zip(values) {
            nzval[slot] += v;
        }
    }

    /// The matrix with `values`.
    pub fn csc(&self, values: &[f64]) -> CscMatrix<f64> {
        let mut nzval = vec![0.0; self.nnz()];
        self.scatter(values, &mut nzval);
        CscMatrix::new(
            self.rows,
            self.cols,
            self.colptr.clone(),
            self.rowval.clone(),
            nzval,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_land_in_column_order_and_repeats_add_up() {
        let mut p = Pattern::new(3, 3);
        p.push(2, 1);
        p.push(0, 0);
        p.push(1, 1);
        p.push(2, 1);
        p.compile();
        assert_eq!(p.nnz(), 3);
        let m = p.csc(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(m.colptr, vec![0, 1, 3, 3]);
        assert_eq!(m.rowval, vec![0, 1, 2]);
        assert_eq!(m.nzval, vec![2.0, 3.0, 5.0]);
        // Explicit zeros stay in the pattern.
        let z = p.csc(&[0.0; 4]);
        assert_eq!(z.nzval.len(), 3);
    }
}
