//! Line and bar plots as inline SVG for `report.html`: labelled axes, ticks, a legend, and
//! vertical marks (keys, phases). Written by hand rather than with a plotting crate: a few
//! hundred bytes of markup per plot, the same bytes every run (numbers printed with fixed
//! precision), and text left to the browser's own sans-serif font (nothing to fetch or embed).

use std::fmt::Write;

/// Plot area: the SVG's size and its margins (left for the y ticks, right for the legend).
const WIDTH: f64 = 680.0;
const HEIGHT: f64 = 300.0;
const LEFT: f64 = 72.0;
const RIGHT: f64 = 170.0;
const TOP: f64 = 30.0;
const BOTTOM: f64 = 46.0;

/// Colours of the series, in order (distinct for colour-blind readers: Okabe-Ito).
pub(crate) const COLOURS: [&str; 6] = ["#0072b2", "#d55e00", "#009e73", "#cc79a7", "#e69f00", "#56b4e9"];

/// One series: a polyline, or dots only.
#[derive(Debug, Clone)]
pub struct Line {
    /// The legend's text.
    pub name: String,
    /// `(x, y)` points.
    pub points: Vec<(f64, f64)>,
    /// Dots at the points instead of a line.
    pub dots: bool,
}

/// A vertical mark: a dashed line at `x` with a short label.
#[derive(Debug, Clone)]
pub(crate) struct Mark {
    /// Where.
    pub x: f64,
    /// Its label (drawn at the top of the plot area).
    pub label: String,
}

/// A line plot.
#[derive(Debug, Clone)]
pub(crate) struct LinePlot {
    /// The `id` of the `<svg>` element (`plot-energy`).
    pub id: String,
    /// The title drawn above.
    pub title: String,
    /// The x axis' label (with its unit).
    pub x_label: String,
    /// The y axis' label (with its unit).
    pub y_label: String,
    /// A logarithmic y axis (values at or below zero are left out).
    pub log_y: bool,
    /// The series.
    pub lines: Vec<Line>,
    /// Vertical marks.
    pub marks: Vec<Mark>,
}

/// A grouped bar plot on a logarithmic axis: per group (a format), one bar per series.
#[derive(Debug, Clone)]
pub(crate) struct BarPlot {
    /// The `id` of the `<svg>` element.
    pub id: String,
    /// The title drawn above.
    pub title: String,
    /// The x axis' label (what the groups are).
    pub x_label: String,
    /// The y axis' label.
    pub y_label: String,
    /// The series' names (the legend).
    pub series: Vec<String>,
    /// Per group: its name and one value per series (none: not written).
    pub groups: Vec<(String, Vec<Option<f64>>)>,
}

/// A number for a label or a coordinate: fixed precision, no `-0`.
fn num(x: f64) -> String {
    let s = format!("{x:.1}");
    if s == "-0.0" {
        "0.0".into()
    } else {
        s
    }
}

/// A tick label: short, exact enough to read; on a log axis always as `2e3`, so the decades
/// read alike.
fn tick_label(x: f64, log: bool) -> String {
    if x == 0.0 {
        return "0".into();
    }
    let a = x.abs();
    if !log && (1e-3..1e5).contains(&a) {
        let s = format!("{x:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        let s = format!("{x:.1e}");
        s.replace(".0e", "e")
    }
}

/// Escape text for SVG and HTML.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// Round ticks covering `[lo, hi]` on a linear axis: multiples of 1, 2 or 5 x 10^k.
fn linear_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let span = (hi - lo).max(f64::MIN_POSITIVE);
    let raw = span / 5.0;
    let magnitude = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * magnitude).find(|s| span / s <= 6.0).unwrap_or(10.0 * magnitude);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// The range of `values`, widened when empty or flat.
fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo <= 1e-12 * hi.abs().max(lo.abs()).max(f64::MIN_POSITIVE) {
        let pad = if lo == 0.0 { 1.0 } else { 0.05 * lo.abs() };
        return (lo - pad, hi + pad);
    }
    (lo, hi)
}

/// At most two points per pixel column of `pts` (in pixels, x increasing): the lowest and the
/// highest, in their order, so a peak of one frame stays while a plot of thousands of frames or
/// iterations keeps a bounded size.
fn thin(pts: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::new();
    let mut k = 0;
    while k < pts.len() {
        let column = pts[k].0.floor();
        let end = k + pts[k..].iter().take_while(|p| p.0.floor() == column).count();
        let group = &pts[k..end];
        let lowest = (0..group.len()).min_by(|&a, &b| group[a].1.total_cmp(&group[b].1)).unwrap_or(0);
        let highest = (0..group.len()).max_by(|&a, &b| group[a].1.total_cmp(&group[b].1)).unwrap_or(0);
        out.push(group[lowest.min(highest)]);
        if lowest != highest {
            out.push(group[lowest.max(highest)]);
        }
        k = end;
    }
    out
}

/// A y axis: maps values to pixels, with its ticks.
struct Axis {
    log: bool,
    lo: f64,
    hi: f64,
    ticks: Vec<f64>,
}

impl Axis {
    fn new(values: impl Iterator<Item = f64>, log: bool, from_zero: bool) -> Axis {
        if log {
            let (lo, hi) = range(values.filter(|v| *v > 0.0).map(f64::log10));
            let (lo, hi) = (lo.floor(), hi.ceil().max(lo.floor() + 1.0));
            let mut ticks: Vec<f64> = (lo as i64..=hi as i64).map(|e| 10f64.powi(e as i32)).collect();
            if hi - lo <= 1.0 {
                // One decade: 2 and 5 too.
                ticks = ticks.iter().flat_map(|t| [*t, 2.0 * t, 5.0 * t]).filter(|t| t.log10() <= hi + 1e-9).collect();
            }
            return Axis { log, lo, hi, ticks };
        }
        let (mut lo, mut hi) = range(values);
        if from_zero && lo > 0.0 {
            lo = 0.0;
        }
        let pad = 0.05 * (hi - lo);
        (lo, hi) = (if from_zero && lo == 0.0 { 0.0 } else { lo - pad }, hi + pad);
        Axis { log, lo, hi, ticks: linear_ticks(lo, hi) }
    }

    /// The pixel of `v` between `a` (at `lo`) and `b` (at `hi`); none for a log axis' v <= 0.
    fn at(&self, v: f64, a: f64, b: f64) -> Option<f64> {
        let u = if self.log {
            if v <= 0.0 {
                return None;
            }
            v.log10()
        } else {
            v
        };
        Some(a + (b - a) * (u - self.lo) / (self.hi - self.lo))
    }
}

/// The frame every plot shares: the SVG element, title, axes with their labels and ticks.
fn frame(out: &mut String, id: &str, title: &str, x_label: &str, y_label: &str, y: &Axis, y_ticks: bool) {
    let (w, h) = (WIDTH - LEFT - RIGHT, HEIGHT - TOP - BOTTOM);
    let _ = write!(
        out,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" class=\"plot\" id=\"{id}\" viewBox=\"0 0 {WIDTH} {HEIGHT}\" width=\"{WIDTH}\" height=\"{HEIGHT}\" role=\"img\" aria-labelledby=\"{id}-title\" font-family=\"sans-serif\" font-size=\"11\">\
<title id=\"{id}-title\">{}</title>\
<text class=\"plot-title\" x=\"{}\" y=\"18\" text-anchor=\"middle\" font-size=\"13\">{}</text>\
<rect x=\"{LEFT}\" y=\"{TOP}\" width=\"{w}\" height=\"{h}\" fill=\"none\" stroke=\"#888\"/>\
<text class=\"axis-label x-label\" x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\
<text class=\"axis-label y-label\" x=\"14\" y=\"{}\" text-anchor=\"middle\" transform=\"rotate(-90 14 {})\">{}</text>",
        escape(title),
        num(LEFT + w / 2.0),
        escape(title),
        num(LEFT + w / 2.0),
        num(HEIGHT - 8.0),
        escape(x_label),
        num(TOP + h / 2.0),
        num(TOP + h / 2.0),
        escape(y_label)
    );
    if y_ticks {
        for &t in &y.ticks {
            let Some(py) = y.at(t, TOP + h, TOP) else { continue };
            let _ = write!(
                out,
                "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"#ddd\"/><text class=\"tick y-tick\" x=\"{}\" y=\"{}\" text-anchor=\"end\">{}</text>",
                num(LEFT),
                num(py),
                num(LEFT + w),
                num(py),
                num(LEFT - 4.0),
                num(py + 4.0),
                tick_label(t, y.log)
            );
        }
    }
}

/// The legend, right of the plot area.
fn legend(out: &mut String, names: &[(&str, bool)]) {
    for (i, (name, dots)) in names.iter().enumerate() {
        let (x, y) = (WIDTH - RIGHT + 12.0, TOP + 10.0 + 18.0 * i as f64);
        let c = COLOURS[i % COLOURS.len()];
        if *dots {
            let _ = write!(out, "<circle cx=\"{}\" cy=\"{}\" r=\"3.5\" fill=\"{c}\"/>", num(x + 9.0), num(y - 4.0));
        } else {
            let _ = write!(
                out,
                "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{c}\" stroke-width=\"2\"/>",
                num(x),
                num(y - 4.0),
                num(x + 18.0),
                num(y - 4.0)
            );
        }
        let _ = write!(out, "<text class=\"legend\" x=\"{}\" y=\"{}\">{}</text>", num(x + 24.0), num(y), escape(name));
    }
}

impl LinePlot {
    /// The plot as one `<svg>` element.
    pub fn svg(&self) -> String {
        let (w, h) = (WIDTH - LEFT - RIGHT, HEIGHT - TOP - BOTTOM);
        let ys = || self.lines.iter().flat_map(|l| l.points.iter().map(|p| p.1));
        // Nothing positive to put on a log axis (W zero: exact keys): a linear one.
        let y = Axis::new(ys(), self.log_y && ys().any(|v| v > 0.0), false);
        let xs = self.lines.iter().flat_map(|l| l.points.iter().map(|p| p.0)).chain(self.marks.iter().map(|m| m.x));
        let (x_lo, x_hi) = range(xs);
        let x = Axis { log: false, lo: x_lo, hi: x_hi, ticks: linear_ticks(x_lo, x_hi) };
        let mut out = String::new();
        frame(&mut out, &self.id, &self.title, &self.x_label, &self.y_label, &y, true);
        for &t in &x.ticks {
            let px = x.at(t, LEFT, LEFT + w).unwrap_or(LEFT);
            let _ = write!(
                out,
                "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"#888\"/><text class=\"tick x-tick\" x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>",
                num(px),
                num(TOP + h),
                num(px),
                num(TOP + h + 4.0),
                num(px),
                num(TOP + h + 16.0),
                tick_label(t, false)
            );
        }
        for m in &self.marks {
            let px = x.at(m.x, LEFT, LEFT + w).unwrap_or(LEFT);
            // Near the right edge the label goes left of its line, clear of the legend.
            let (lx, anchor) = if px > LEFT + 0.9 * w { (px - 2.0, "end") } else { (px + 2.0, "start") };
            let _ = write!(
                out,
                "<line class=\"mark\" x1=\"{}\" y1=\"{TOP}\" x2=\"{}\" y2=\"{}\" stroke=\"#999\" stroke-dasharray=\"4 3\"/><text class=\"mark-label\" x=\"{}\" y=\"{}\" text-anchor=\"{anchor}\" font-size=\"9\" fill=\"#555\">{}</text>",
                num(px),
                num(px),
                num(TOP + h),
                num(lx),
                num(TOP + 9.0),
                escape(&m.label)
            );
        }
        for (i, line) in self.lines.iter().enumerate() {
            let c = COLOURS[i % COLOURS.len()];
            let pts: Vec<(f64, f64)> =
                line.points.iter().filter_map(|&(px, py)| Some((x.at(px, LEFT, LEFT + w)?, y.at(py, TOP + h, TOP)?))).collect();
            let pts = if line.dots { pts } else { thin(&pts) };
            if line.dots || pts.len() == 1 {
                for (px, py) in &pts {
                    let _ = write!(out, "<circle cx=\"{}\" cy=\"{}\" r=\"3.5\" fill=\"{c}\"/>", num(*px), num(*py));
                }
            } else if !pts.is_empty() {
                let path: Vec<String> = pts.iter().map(|(px, py)| format!("{},{}", num(*px), num(*py))).collect();
                let _ = write!(out, "<polyline class=\"series\" fill=\"none\" stroke=\"{c}\" stroke-width=\"1.5\" points=\"{}\"/>", path.join(" "));
            }
        }
        let names: Vec<(&str, bool)> = self.lines.iter().map(|l| (l.name.as_str(), l.dots)).collect();
        legend(&mut out, &names);
        out.push_str("</svg>");
        out
    }
}

impl BarPlot {
    /// The plot as one `<svg>` element.
    pub fn svg(&self) -> String {
        let (w, h) = (WIDTH - LEFT - RIGHT, HEIGHT - TOP - BOTTOM);
        let values = self.groups.iter().flat_map(|g| g.1.iter().flatten().copied());
        let y = Axis::new(values, true, false);
        let mut out = String::new();
        frame(&mut out, &self.id, &self.title, &self.x_label, &self.y_label, &y, true);
        let group_w = w / self.groups.len().max(1) as f64;
        let bar_w = 0.8 * group_w / self.series.len().max(1) as f64;
        for (g, (name, bars)) in self.groups.iter().enumerate() {
            let gx = LEFT + g as f64 * group_w;
            let _ = write!(
                out,
                "<text class=\"tick x-tick\" x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>",
                num(gx + group_w / 2.0),
                num(TOP + h + 16.0),
                escape(name)
            );
            for (i, v) in bars.iter().enumerate() {
                let Some(top) = v.and_then(|v| y.at(v, TOP + h, TOP)) else { continue };
                let top = top.max(TOP);
                let _ = write!(
                    out,
                    "<rect class=\"bar\" x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"{}\"><title>{}: {}</title></rect>",
                    num(gx + 0.1 * group_w + i as f64 * bar_w),
                    num(top),
                    num(bar_w - 1.0),
                    num(TOP + h - top),
                    COLOURS[i % COLOURS.len()],
                    escape(&self.series[i]),
                    super::markdown::human_bytes(v.unwrap_or(0.0) as u64)
                );
            }
        }
        let names: Vec<(&str, bool)> = self.series.iter().map(|s| (s.as_str(), false)).collect();
        legend(&mut out, &names);
        out.push_str("</svg>");
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn energy() -> LinePlot {
        LinePlot {
            id: "plot-energy".into(),
            title: "W per iteration".into(),
            x_label: "iteration".into(),
            y_label: "W (log scale)".into(),
            log_y: true,
            lines: vec![Line { name: "W".into(), points: (0..20).map(|i| (i as f64, 3e4 * 0.7f64.powi(i))).collect(), dots: false }],
            marks: vec![Mark { x: 8.0, label: "quasi-Newton".into() }],
        }
    }

    #[test]
    fn axes_are_labelled() {
        let svg = energy().svg();
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>"));
        assert!(svg.contains(">iteration</text>") && svg.contains(">W (log scale)</text>"));
        // Decades on the log axis: 1e1 .. 1e5, and x ticks.
        for t in ["1e1", "1e2", "1e3", "1e4", "1e5"] {
            assert!(svg.contains(&format!(">{t}</text>")), "{t} missing in {svg}");
        }
        assert!(svg.contains("class=\"tick x-tick\"") && svg.contains(">quasi-Newton</text>"));
        let bars = BarPlot {
            id: "plot-bytes".into(),
            title: "bytes".into(),
            x_label: "format".into(),
            y_label: "bytes (log scale)".into(),
            series: vec!["input".into(), "blendshape".into()],
            groups: vec![("usda".into(), vec![Some(12_000.0), Some(70_000.0)]), ("glb".into(), vec![Some(12_000.0), None])],
        };
        let svg = bars.svg();
        assert_eq!(svg.matches("<rect class=\"bar\"").count(), 3);
        assert!(svg.contains(">format</text>") && svg.contains(">bytes (log scale)</text>") && svg.contains(">usda</text>"));
    }

    #[test]
    fn thinning_keeps_peaks_and_bounds_the_points() {
        // 100 000 frames over 438 px, one spike.
        let pts: Vec<(f64, f64)> =
            (0..100_000).map(|i| (72.0 + 438.0 * i as f64 / 100_000.0, if i == 51_234 { 40.0 } else { 200.0 + (i % 7) as f64 })).collect();
        let thinned = thin(&pts);
        assert!(thinned.len() <= 2 * 439, "{}", thinned.len());
        assert!(thinned.contains(&pts[51_234]), "the spike stays");
        assert!(thinned.windows(2).all(|w| w[0].0 <= w[1].0), "in order");
        // Few points: all of them.
        let few = [(72.0, 1.0), (80.5, 2.0), (90.0, 3.0)];
        assert_eq!(thin(&few), few);
    }

    #[test]
    fn same_bytes_every_time() {
        assert_eq!(energy().svg(), energy().svg());
        assert_eq!(tick_label(0.25, false), "0.25");
        assert_eq!(tick_label(2e-8, false), "2e-8");
        assert_eq!(tick_label(1e4, true), "1e4");
        assert_eq!(linear_ticks(0.0, 2.0), vec![0.0, 0.5, 1.0, 1.5, 2.0]);
    }
}
