//! Plots for the report of a run, as SVG: line plots (axes with round tick values,
//! a legend, lines broken at missing values) and timelines (labelled intervals per
//! row, such as the behaviours of each subsystem over time). Output is a pure
//! function of the data (byte-stable), so a report can be compared across runs.
//!
//! Written here rather than taken from a plotting crate: the report needs two kinds
//! of chart, without fonts or a rasteriser, and byte-stable text.

use std::fmt::Write;

/// Colours of series, in order.
pub const PALETTE: [&str; 6] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b",
];

const WIDTH: f64 = 760.0;
const HEIGHT: f64 = 420.0;
const LEFT: f64 = 70.0;
const RIGHT: f64 = 150.0;
const TOP: f64 = 40.0;
const BOTTOM: f64 = 50.0;

/// One line of a plot; `None` points break the line.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Stroke colour.
    pub color: &'static str,
    /// Dashed stroke.
    pub dashed: bool,
    /// The points.
    pub points: Vec<Option<(f64, f64)>>,
}

impl Series {
    /// A solid line.
    pub fn new(
        name: impl Into<String>,
        color: &'static str,
        points: Vec<Option<(f64, f64)>>,
    ) -> Self {
        Series {
            name: name.into(),
            color,
            dashed: false,
            points,
        }
    }

    /// A solid line of a point for each of a run's `rows` (its samples, say),
    /// `None` where `point` has none (a break in the line).
    pub fn of<T>(
        name: impl Into<String>,
        color: &'static str,
        rows: impl IntoIterator<Item = T>,
        point: impl FnMut(T) -> Option<(f64, f64)>,
    ) -> Self {
        Series::new(name, color, rows.into_iter().map(point).collect())
    }

    /// The same line, dashed.
    pub fn dashed(mut self) -> Self {
        self.dashed = true;
        self
    }
}

/// A labelled point drawn as a marker.
#[derive(Clone, Debug)]
pub struct Marker {
    /// Where.
    pub at: (f64, f64),
    /// Label next to it.
    pub label: String,
}

/// A plot.
#[derive(Clone, Debug, Default)]
pub struct Plot {
    /// Title.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the y axis.
    pub y_label: String,
    /// Same scale on both axes (a map).
    pub equal_aspect: bool,
    /// The lines.
    pub series: Vec<Series>,
    /// Markers.
    pub markers: Vec<Marker>,
}

/// Round tick positions covering `[lo, hi]`.
pub fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    let span = (hi - lo).abs().max(1e-12);
    let raw = span / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|i| i as f64 * step).collect()
}

fn fmt_tick(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

impl Plot {
    fn bounds(&self) -> (f64, f64, f64, f64) {
        let mut b = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        let pts = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().flatten().copied())
            .chain(self.markers.iter().map(|m| m.at));
        for (x, y) in pts.filter(|(x, y)| x.is_finite() && y.is_finite()) {
            b = (b.0.min(x), b.1.max(x), b.2.min(y), b.3.max(y));
        }
        if !b.0.is_finite() {
            return (0.0, 1.0, 0.0, 1.0);
        }
        let pad = |lo: f64, hi: f64| {
            let d = (hi - lo).max(1e-9) * 0.05;
            (lo - d, hi + d)
        };
        let (x0, x1) = pad(b.0, b.1);
        let (y0, y1) = pad(b.2, b.3);
        if !self.equal_aspect {
            return (x0, x1, y0, y1);
        }
        // Grow the smaller span so that one metre is as long on both axes.
        let (w, h) = (WIDTH - LEFT - RIGHT, HEIGHT - TOP - BOTTOM);
        let scale = ((x1 - x0) / w).max((y1 - y0) / h);
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        (
            cx - scale * w / 2.0,
            cx + scale * w / 2.0,
            cy - scale * h / 2.0,
            cy + scale * h / 2.0,
        )
    }

    /// The plot as an SVG document.
    pub fn to_svg(&self) -> String {
        let (x0, x1, y0, y1) = self.bounds();
        let area = Area {
            x: (x0, x1),
            y: (y0, y1),
            w: WIDTH - LEFT - RIGHT,
            h: HEIGHT - TOP - BOTTOM,
        };
        let mut s = svg_start(HEIGHT, LEFT + area.w / 2.0, &self.title);
        self.grid(&mut s, &area);
        self.lines(&mut s, &area);
        self.markers(&mut s, &area);
        self.legend(&mut s, &area);
        s.push_str("</svg>\n");
        s
    }

    /// Grid lines at the ticks with their values, the frame and the axis labels.
    fn grid(&self, s: &mut String, a: &Area) {
        let (w, h) = (a.w, a.h);
        for t in ticks(a.x.0, a.x.1, 8) {
            let x = a.px(t);
            let _ = writeln!(
                s,
                r##"<line x1="{x:.1}" y1="{TOP}" x2="{x:.1}" y2="{:.1}" stroke="#e0e0e0"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
                TOP + h,
                TOP + h + 16.0,
                fmt_tick(t)
            );
        }
        for t in ticks(a.y.0, a.y.1, 6) {
            let y = a.py(t);
            let _ = writeln!(
                s,
                r##"<line x1="{LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#e0e0e0"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
                LEFT + w,
                LEFT - 6.0,
                y + 4.0,
                fmt_tick(t)
            );
        }
        let _ = writeln!(
            s,
            r#"<rect x="{LEFT}" y="{TOP}" width="{w}" height="{h}" fill="none" stroke="black"/>"#
        );
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            LEFT + w / 2.0,
            HEIGHT - 12.0,
            escape(&self.x_label)
        );
        let _ = writeln!(
            s,
            r#"<text transform="translate(18,{:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
            TOP + h / 2.0,
            escape(&self.y_label)
        );
    }

    /// Each series as one path, lifted at missing or non-finite points.
    fn lines(&self, s: &mut String, a: &Area) {
        for series in &self.series {
            let mut d = String::new();
            let mut pen_down = false;
            for p in &series.points {
                match p {
                    Some((x, y)) if x.is_finite() && y.is_finite() => {
                        let _ = write!(
                            d,
                            "{}{:.1},{:.1} ",
                            if pen_down { "L" } else { "M" },
                            a.px(*x),
                            a.py(*y)
                        );
                        pen_down = true;
                    }
                    _ => pen_down = false,
                }
            }
            if !d.is_empty() {
                let _ = writeln!(
                    s,
                    r#"<path d="{}" fill="none" stroke="{}" stroke-width="1.5"{}/>"#,
                    d.trim_end(),
                    series.color,
                    series.dash()
                );
            }
        }
    }

    /// The markers, each a dot with its label.
    fn markers(&self, s: &mut String, a: &Area) {
        for m in &self.markers {
            let (x, y) = (a.px(m.at.0), a.py(m.at.1));
            let _ = writeln!(
                s,
                r#"<circle cx="{x:.1}" cy="{y:.1}" r="4" fill="black"/><text x="{:.1}" y="{:.1}">{}</text>"#,
                x + 6.0,
                y - 6.0,
                escape(&m.label)
            );
        }
    }

    /// The legend, right of the plot area: a stroke sample and the name per series.
    fn legend(&self, s: &mut String, a: &Area) {
        for (i, series) in self.series.iter().enumerate() {
            let y = TOP + 10.0 + 18.0 * i as f64;
            let x = LEFT + a.w + 12.0;
            let _ = writeln!(
                s,
                r#"<line x1="{x:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{}" stroke-width="2"{}/><text x="{:.1}" y="{:.1}">{}</text>"#,
                x + 24.0,
                series.color,
                series.dash(),
                x + 30.0,
                y + 4.0,
                escape(&series.name)
            );
        }
    }
}

/// The plot area: the data ranges and the size they are drawn at.
struct Area {
    x: (f64, f64),
    y: (f64, f64),
    w: f64,
    h: f64,
}

impl Area {
    /// The horizontal position of `x`.
    fn px(&self, x: f64) -> f64 {
        LEFT + (x - self.x.0) / (self.x.1 - self.x.0) * self.w
    }

    /// The vertical position of `y` (up is up).
    fn py(&self, y: f64) -> f64 {
        TOP + self.h - (y - self.y.0) / (self.y.1 - self.y.0) * self.h
    }
}

impl Series {
    /// The stroke attribute of a dashed series (empty for a solid one).
    fn dash(&self) -> &'static str {
        if self.dashed {
            r#" stroke-dasharray="6,4""#
        } else {
            ""
        }
    }
}

/// The start of an SVG document `height` tall: the root element, a white
/// background, and `title` centred on `title_x`.
fn svg_start(height: f64, title_x: f64, title: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{height}" viewBox="0 0 {WIDTH} {height}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(
        s,
        r#"<rect width="{WIDTH}" height="{height}" fill="white"/>"#
    );
    let _ = writeln!(
        s,
        r#"<text x="{title_x}" y="22" font-size="15" text-anchor="middle">{}</text>"#,
        escape(title)
    );
    s
}

/// One row of a timeline: labelled intervals `[t0, t1)` with a colour.
#[derive(Clone, Debug)]
pub struct Row {
    /// Row label.
    pub name: String,
    /// `(t0, t1, label, colour)`.
    pub spans: Vec<(f64, f64, String, &'static str)>,
}

impl Row {
    /// The row of a value sampled over time (`(t, value)` in time order): a
    /// span for each run of equal values, from its first sample to the next
    /// run's first (the last run's to `end`), labelled and coloured by
    /// `style` (a subsystem's behaviour, the task it executes).
    pub fn of_changes<V: PartialEq>(
        name: impl Into<String>,
        samples: impl IntoIterator<Item = (f64, V)>,
        end: f64,
        style: impl Fn(&V) -> (String, &'static str),
    ) -> Row {
        let spans = runs(samples).into_iter().map(|(t0, t1, v)| {
            let (label, colour) = style(&v);
            (t0, t1.unwrap_or(end), label, colour)
        });
        Row {
            name: name.into(),
            spans: spans.collect(),
        }
    }

    /// The row of instants (`(t, label)`: messages received, say), each a
    /// narrow span in `colour` on a timeline that ends at `end`.
    pub fn of_instants(
        name: impl Into<String>,
        instants: impl IntoIterator<Item = (f64, String)>,
        end: f64,
        colour: &'static str,
    ) -> Row {
        Row {
            name: name.into(),
            spans: instants
                .into_iter()
                .map(|(t, label)| (t, t + end * 0.004, label, colour))
                .collect(),
        }
    }
}

/// The runs of equal values of a value sampled over time (`(t, value)` in
/// time order): each run's first instant, the next run's (`None` for the
/// last run) and its value. What a timeline row draws
/// ([`Row::of_changes`]); the intervals a condition held, kept `true`.
pub fn runs<V: PartialEq>(
    samples: impl IntoIterator<Item = (f64, V)>,
) -> Vec<(f64, Option<f64>, V)> {
    let mut runs: Vec<(f64, Option<f64>, V)> = Vec::new();
    for (t, v) in samples {
        match runs.last_mut() {
            Some(last) if last.2 == v => {}
            Some(last) => {
                last.1 = Some(t);
                runs.push((t, None, v));
            }
            None => runs.push((t, None, v)),
        }
    }
    runs
}

/// One series a name, coloured from the [`PALETTE`] in turn, the `i`-th of
/// the points `points(i)` (the components of a vector over time, say).
pub fn series_each(
    names: &[&str],
    points: impl Fn(usize) -> Vec<Option<(f64, f64)>>,
) -> Vec<Series> {
    names
        .iter()
        .enumerate()
        .map(|(i, n)| Series::new(*n, PALETTE[i % PALETTE.len()], points(i)))
        .collect()
}

/// One series per name over a run's `rows` (its samples, say): `values` of a
/// row gives the row's instant and a value per series, the `i`-th series
/// drawing the `i`-th (the components of a vector over time). Coloured as
/// [`series_each`] colours them.
pub fn series_over<T, const N: usize>(
    names: [&str; N],
    rows: &[T],
    values: impl Fn(&T) -> (f64, [f64; N]),
) -> Vec<Series> {
    let points: Vec<(f64, [f64; N])> = rows.iter().map(values).collect();
    series_each(&names, |i| {
        points.iter().map(|(t, v)| Some((*t, v[i]))).collect()
    })
}

/// A timeline of rows (FSM behaviours over time, fragments being executed).
pub fn timeline(title: &str, rows: &[Row], t_end: f64) -> String {
    let w = WIDTH - LEFT - 20.0;
    let row_h = 34.0;
    let height = TOP + rows.len() as f64 * (row_h + 10.0) + BOTTOM;
    let px = |t: f64| LEFT + 30.0 + t / t_end.max(1e-9) * (w - 30.0);
    let mut s = svg_start(height, WIDTH / 2.0, title);
    for (i, row) in rows.iter().enumerate() {
        let y = TOP + i as f64 * (row_h + 10.0);
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"#,
            LEFT + 22.0,
            y + row_h / 2.0 + 4.0,
            escape(&row.name)
        );
        for (t0, t1, label, color) in &row.spans {
            let (x0, x1) = (px(*t0), px(*t1));
            let _ = writeln!(
                s,
                r#"<rect x="{x0:.1}" y="{y:.1}" width="{:.1}" height="{row_h}" fill="{color}" fill-opacity="0.75"/>"#,
                (x1 - x0).max(0.5)
            );
            if x1 - x0 > 8.0 * label.len() as f64 {
                let _ = writeln!(
                    s,
                    r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" fill="white">{}</text>"#,
                    (x0 + x1) / 2.0,
                    y + row_h / 2.0 + 4.0,
                    escape(label)
                );
            }
        }
    }
    let axis_y = TOP + rows.len() as f64 * (row_h + 10.0);
    for t in ticks(0.0, t_end, 10) {
        let _ = writeln!(
            s,
            r#"<line x1="{x:.1}" y1="{axis_y:.1}" x2="{x:.1}" y2="{:.1}" stroke="black"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            axis_y + 5.0,
            axis_y + 18.0,
            fmt_tick(t),
            x = px(t)
        );
    }
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">time [s]</text>"#,
        WIDTH / 2.0,
        axis_y + 36.0
    );
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_cover_the_range() {
        assert_eq!(ticks(0.0, 10.0, 5), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        let t = ticks(-0.13, 0.41, 6);
        assert!(t.iter().all(|v| (v * 10.0).round() / 10.0 - v < 1e-12));
        assert_eq!(fmt_tick(-0.0), "0");
        assert_eq!(fmt_tick(2.5), "2.5");
    }

    #[test]
    fn lines_break_at_missing_points_and_output_is_stable() {
        let plot = Plot {
            title: "t <1>".into(),
            series: vec![Series::new(
                "a",
                PALETTE[0],
                vec![Some((0.0, 0.0)), Some((1.0, 1.0)), None, Some((2.0, 0.0))],
            )],
            ..Plot::default()
        };
        let svg = plot.to_svg();
        let path = svg.lines().find(|l| l.starts_with("<path")).unwrap_or("");
        assert_eq!(path.matches('M').count(), 2, "{path}");
        assert!(svg.contains("t &lt;1&gt;"));
        assert_eq!(svg, plot.to_svg());
    }

    #[test]
    fn a_row_of_changes_has_a_span_for_each_run_of_equal_values() {
        let samples = [(0.0, 'a'), (1.0, 'a'), (2.0, 'b'), (3.0, 'a'), (4.0, 'a')];
        let row = Row::of_changes("c1", samples, 5.0, |v| (v.to_string(), "#000000"));
        let spans: Vec<_> = row.spans.iter().map(|s| (s.0, s.1, s.2.as_str())).collect();
        assert_eq!(spans, [(0.0, 2.0, "a"), (2.0, 3.0, "b"), (3.0, 5.0, "a")]);
        assert!(
            Row::of_changes("c1", Vec::<(f64, u8)>::new(), 1.0, |_| (String::new(), ""))
                .spans
                .is_empty()
        );
        let acks = Row::of_instants("a2", [(1.0, "ack 1".to_owned())], 10.0, "#d62728");
        assert_eq!(
            acks.spans,
            [(1.0, 1.0 + 10.0 * 0.004, "ack 1".to_owned(), "#d62728")]
        );
    }

    #[test]
    fn runs_end_where_the_next_begins() {
        let lost = [
            (0.0, false),
            (1.0, true),
            (2.0, true),
            (3.0, false),
            (4.0, true),
        ];
        let held: Vec<_> = runs(lost)
            .into_iter()
            .filter(|r| r.2)
            .map(|(from, to, _)| (from, to))
            .collect();
        assert_eq!(held, [(1.0, Some(3.0)), (4.0, None)]);
    }

    #[test]
    fn a_series_of_rows_has_a_point_or_a_break_for_each() {
        let rows = [(0.0, Some(1.0)), (1.0, None), (2.0, Some(3.0))];
        let s = Series::of("y", PALETTE[3], &rows, |(t, y)| y.map(|y| (*t, y))).dashed();
        assert_eq!(s.points, [Some((0.0, 1.0)), None, Some((2.0, 3.0))]);
        assert_eq!(
            (s.name.as_str(), s.color, s.dashed),
            ("y", PALETTE[3], true)
        );
    }

    #[test]
    fn series_over_rows_draw_each_component() {
        let rows = [(0.0, [1.0, 2.0]), (0.5, [3.0, 4.0])];
        let s = series_over(["a", "b"], &rows, |r| (r.0, r.1));
        assert_eq!(s.len(), 2);
        assert_eq!(s[0].points, [Some((0.0, 1.0)), Some((0.5, 3.0))]);
        assert_eq!(s[1].points, [Some((0.0, 2.0)), Some((0.5, 4.0))]);
        assert_eq!((s[0].name.as_str(), s[1].color), ("a", PALETTE[1]));
    }

    #[test]
    fn series_each_takes_the_palette_in_turn() {
        let s = series_each(&["x", "y"], |i| vec![Some((0.0, i as f64))]);
        assert_eq!((s[0].color, s[1].color), (PALETTE[0], PALETTE[1]));
        assert_eq!(s[1].points, [Some((0.0, 1.0))]);
    }
}
