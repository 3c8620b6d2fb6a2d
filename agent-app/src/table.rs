//! A run's rows as a CSV table: the samples a program keeps (one per
//! activation of a controller, say) written for a spreadsheet or a plotting
//! script, each column named and each number with the digits the program
//! chooses.
//!
//! ```
//! use agent_app::table::Csv;
//!
//! struct Sample {
//!     t: f64,
//!     pose: [f64; 2],
//!     mode: &'static str,
//! }
//! let rows = [
//!     Sample { t: 0.02, pose: [1.0, -0.5], mode: "track" },
//!     Sample { t: 0.04, pose: [f64::NAN, 0.25], mode: "hold, waiting" },
//! ];
//! let csv = Csv::new()
//!     .number("t", 3, |s: &Sample| s.t)
//!     .numbers(["x", "y"], 2, |s: &Sample| s.pose)
//!     .text("mode", |s: &Sample| s.mode.to_owned())
//!     .write(&rows);
//! assert_eq!(
//!     csv,
//!     "t,x,y,mode\n0.020,1.00,-0.50,track\n0.040,NaN,0.25,\"hold, waiting\"\n"
//! );
//! ```

use std::fmt::Write as _;

/// One column's cell of a row, appended to the line.
type Cell<'a, T> = Box<dyn Fn(&T, &mut String) + 'a>;

/// A CSV table of rows of `T`: its columns, each a name and how a row's cell
/// is written. Numbers are written with a fixed number of decimals (`NaN`
/// for a value that is missing), text is quoted when it holds a comma, a
/// quote or a line break (RFC 4180).
pub struct Csv<'a, T> {
    names: Vec<String>,
    cells: Vec<Cell<'a, T>>,
}

impl<T> Default for Csv<'_, T> {
    fn default() -> Self {
        Csv {
            names: Vec::new(),
            cells: Vec::new(),
        }
    }
}

impl<T> std::fmt::Debug for Csv<'_, T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Csv").field("columns", &self.names).finish()
    }
}

impl<'a, T> Csv<'a, T> {
    /// A table with no column yet.
    pub fn new() -> Self {
        Csv::default()
    }

    /// A column of numbers, `value` of each row with `decimals` digits after
    /// the point.
    pub fn number(self, name: &str, decimals: usize, value: impl Fn(&T) -> f64 + 'a) -> Self {
        self.numbers([name], decimals, move |row| [value(row)])
    }

    /// One column per name, the `i`-th of `values` of each row (the
    /// components of a vector, say), each with `decimals` digits.
    pub fn numbers<const N: usize>(
        mut self,
        names: [&str; N],
        decimals: usize,
        values: impl Fn(&T) -> [f64; N] + 'a,
    ) -> Self {
        self.names.extend(names.iter().map(|n| (*n).to_owned()));
        self.cells.push(Box::new(move |row, line| {
            for (i, v) in values(row).iter().enumerate() {
                if i > 0 {
                    line.push(',');
                }
                let _ = write!(line, "{v:.decimals$}");
            }
        }));
        self
    }

    /// A column of text, `value` of each row (empty for nothing), quoted
    /// when it needs to be.
    pub fn text(mut self, name: &str, value: impl Fn(&T) -> String + 'a) -> Self {
        self.names.push(name.to_owned());
        self.cells.push(Box::new(move |row, line| {
            line.push_str(&quoted(&value(row)))
        }));
        self
    }

    /// The table of `rows`: the header line of the column names, then a line
    /// per row, each ended by `\n`.
    pub fn write<'r>(&self, rows: impl IntoIterator<Item = &'r T>) -> String
    where
        T: 'r,
    {
        let names: Vec<String> = self.names.iter().map(|n| quoted(n)).collect();
        let mut s = names.join(",");
        s.push('\n');
        for row in rows {
            for (i, cell) in self.cells.iter().enumerate() {
                if i > 0 {
                    s.push(',');
                }
                cell(row, &mut s);
            }
            s.push('\n');
        }
        s
    }
}

/// `text` as a CSV field: as it is, or quoted (its quotes doubled) when it
/// holds a comma, a quote or a line break.
fn quoted(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_come_in_order_with_their_decimals() {
        let rows = [(1.0, [2.0, 3.0], 4u8), (0.5, [f64::NAN, -1.0], 5)];
        let csv = Csv::new()
            .number("t", 3, |r: &(f64, [f64; 2], u8)| r.0)
            .numbers(["a", "b"], 1, |r: &(f64, [f64; 2], u8)| r.1)
            .text("k", |r: &(f64, [f64; 2], u8)| format!("B{}", r.2))
            .write(&rows);
        assert_eq!(csv, "t,a,b,k\n1.000,2.0,3.0,B4\n0.500,NaN,-1.0,B5\n");
    }

    #[test]
    fn text_is_quoted_only_when_it_must_be() {
        let rows = ["plain", "a,b", "say \"hi\"", "two\nlines", ""];
        let csv = Csv::new()
            .text("what", |r: &&str| (*r).to_owned())
            .write(&rows);
        let lines: Vec<&str> = csv.split('\n').collect();
        assert_eq!(
            lines,
            [
                "what",
                "plain",
                "\"a,b\"",
                "\"say \"\"hi\"\"\"",
                "\"two",
                "lines\"",
                "",
                ""
            ]
        );
    }

    #[test]
    fn a_table_without_rows_is_its_header() {
        let csv: Csv<'_, f64> = Csv::new().number("x", 2, |v| *v).number("y", 2, |v| -v);
        assert_eq!(csv.write(&[]), "x,y\n");
        assert_eq!(format!("{csv:?}"), "Csv { columns: [\"x\", \"y\"] }");
    }
}
