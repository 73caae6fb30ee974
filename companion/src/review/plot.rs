//! Inline SVG drawing: line plots over time and the map of the flown track. Lines are
//! decimated to a bounded number of points; every line gets its own colour and dash pattern.

use super::text::esc;
use std::fmt::Write;

/// Points kept per line at most (the stride doubles whenever this many are held).
pub const MAX_POINTS: usize = 2000;

/// Keeps every `stride`-th point of a line, doubling the stride (and dropping every other kept
/// point) when [`MAX_POINTS`] are held; the last point pushed is always drawn.
#[derive(Debug, Clone, Default)]
pub struct Decimator {
    stride: u64,
    seen: u64,
    points: Vec<(f64, f64)>,
    last: Option<(f64, f64)>,
}

impl Decimator {
    pub fn push(&mut self, x: f64, y: f64) {
        if self.stride == 0 {
            self.stride = 1;
        }
        if self.seen.is_multiple_of(self.stride) {
            self.points.push((x, y));
            if self.points.len() >= MAX_POINTS {
                let mut k = 0;
                self.points.retain(|_| {
                    k += 1;
                    k % 2 == 1
                });
                self.stride *= 2;
            }
        }
        self.seen += 1;
        self.last = Some((x, y));
    }

    /// The points to draw, the last one included.
    pub fn points(&self) -> Vec<(f64, f64)> {
        let mut p = self.points.clone();
        if let Some(l) = self.last
            && p.last() != Some(&l)
        {
            p.push(l);
        }
        p
    }

    pub fn is_empty(&self) -> bool {
        self.seen == 0
    }
}

/// Twelve colours distinct for colour-blind readers too (Paul Tol's "muted" and "bright" sets).
pub const PALETTE: [&str; 12] = [
    "#4477aa", "#ee6677", "#228833", "#ccbb44", "#66ccee", "#aa3377", "#332288", "#117733",
    "#999933", "#882255", "#cc6677", "#000000",
];
/// Dash patterns, taken in turn once the colours run out.
pub const DASHES: [&str; 4] = ["", "7 3", "2 2", "9 3 2 3"];

/// Colour and dash of line `k`: distinct for the first 48 lines.
pub fn style(k: usize) -> (&'static str, &'static str) {
    (
        PALETTE[k % PALETTE.len()],
        DASHES[(k / PALETTE.len()) % DASHES.len()],
    )
}

/// A number as the report prints it: whole above 1000 or when whole, else 1 or 2 decimals.
pub(super) fn num(v: f64) -> String {
    if !v.is_finite() {
        return "–".into();
    }
    if v.abs() >= 1000.0 || v == v.trunc() {
        format!("{v:.0}")
    } else if v.abs() >= 10.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

/// A line on a plot.
pub(crate) struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub dashed: bool,
}

/// A vertical marker at a time.
pub(crate) struct VMark {
    pub t: f64,
    pub class: &'static str,
    pub text: String,
}

/// "Nice" tick values covering [lo, hi] (steps of 1, 2 or 5 times a power of ten).
pub fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater)
        || !lo.is_finite()
        || !hi.is_finite()
    {
        return vec![lo];
    }
    let raw = (hi - lo) / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let m = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .find(|m| m * mag >= raw)
        .unwrap_or(10.0);
    let step = m * mag;
    // Tick k is k*m*mag; for mag < 1 divide by 1/mag (an integer) so 3 * 0.2 prints as 0.6.
    let at = |k: f64| {
        if mag < 1.0 {
            k * m / (1.0 / mag).round()
        } else {
            k * m * mag
        }
    };
    let mut out = Vec::new();
    let mut k = (lo / step).ceil();
    while at(k) <= hi + step * 1e-9 && out.len() < 1000 {
        let v = at(k);
        out.push(if v == 0.0 { 0.0 } else { v });
        k += 1.0;
    }
    out
}

fn swatch(color: &str, dash: &str) -> String {
    format!(
        r#"<svg class="swatch" width="26" height="8" viewBox="0 0 26 8"><line x1="0" y1="4" x2="26" y2="4" stroke="{}" stroke-width="2.2"{}/></svg>"#,
        esc(color),
        if dash.is_empty() {
            String::new()
        } else {
            format!(r#" stroke-dasharray="{}""#, esc(dash))
        }
    )
}

/// An inline SVG line plot inside a `<figure class="plot" id=...>`, with data attributes
/// giving the number of series and points drawn.
pub(crate) fn svg_plot(
    id: &str,
    title: &str,
    unit: &str,
    series: &[Series],
    y_fixed: Option<(f64, f64)>,
    marks: &[VMark],
) -> String {
    let series: Vec<&Series> = series.iter().filter(|s| !s.points.is_empty()).collect();
    let total: usize = series.iter().map(|s| s.points.len()).sum();
    let mut o = String::new();
    let _ = write!(
        o,
        r#"<figure class="plot" id="{}" data-series="{}" data-points="{}"><figcaption>{}</figcaption>"#,
        esc(id),
        series.len(),
        total,
        esc(title)
    );
    if total == 0 {
        o.push_str(r#"<p class="no-data">no data in this log</p></figure>"#);
        return o;
    }
    let (w, h) = (900.0, 240.0);
    let (ml, mr, mt, mb) = (56.0, 12.0, 10.0, 28.0);
    let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
    for &(x, y) in series.iter().flat_map(|s| s.points.iter()) {
        if x.is_finite() {
            x0 = x0.min(x);
            x1 = x1.max(x);
        }
        if y.is_finite() {
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if !x0.is_finite() {
        x0 = 0.0;
    }
    if !y0.is_finite() {
        (y0, y1) = (0.0, 1.0);
    }
    if let Some((a, b)) = y_fixed {
        y0 = y0.min(a);
        y1 = y1.max(b);
    } else {
        let pad = if y1 > y0 {
            (y1 - y0) * 0.08
        } else {
            y0.abs().max(1.0) * 0.1
        };
        y0 -= pad;
        y1 += pad;
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    let sx = |x: f64| ml + (x - x0) / (x1 - x0) * (w - ml - mr);
    let sy = |y: f64| mt + (1.0 - (y - y0) / (y1 - y0)) * (h - mt - mb);
    let _ = write!(
        o,
        r#"<svg viewBox="0 0 {w} {h}" xmlns="http://www.w3.org/2000/svg" role="img" aria-label="{}">"#,
        esc(title)
    );
    for t in ticks(y0, y1, 5) {
        let y = sy(t);
        let _ = write!(
            o,
            r##"<line class="grid" x1="{ml}" x2="{}" y1="{y:.1}" y2="{y:.1}"/><text class="tick" x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
            w - mr,
            ml - 6.0,
            y + 4.0,
            num(t)
        );
    }
    for t in ticks(x0, x1, 10) {
        let x = sx(t);
        let _ = write!(
            o,
            r##"<line class="grid" x1="{x:.1}" x2="{x:.1}" y1="{mt}" y2="{}"/><text class="tick" x="{x:.1}" y="{}" text-anchor="middle">{}</text>"##,
            h - mb,
            h - mb + 16.0,
            num(t)
        );
    }
    let _ = write!(
        o,
        r#"<text class="axis-label" x="{}" y="{}" text-anchor="end">time (s)</text><text class="axis-label" x="4" y="{}">{}</text>"#,
        w - mr,
        h - 2.0,
        mt + 8.0,
        esc(unit)
    );
    for m in marks {
        if m.t < x0 || m.t > x1 {
            continue;
        }
        let x = sx(m.t);
        let _ = write!(
            o,
            r#"<line class="vmark {}" x1="{x:.1}" x2="{x:.1}" y1="{mt}" y2="{}"><title>{}</title></line>"#,
            esc(m.class),
            h - mb,
            esc(&format!("t = {} s: {}", num(m.t), m.text))
        );
    }
    for (k, s) in series.iter().enumerate() {
        let (color, dash) = if s.dashed {
            ("#555555", "6 4")
        } else {
            style(k)
        };
        let pts: Vec<String> = s
            .points
            .iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|&(x, y)| format!("{:.1},{:.1}", sx(x), sy(y)))
            .collect();
        let last = s.points.last().map(|p| p.1).unwrap_or(f64::NAN);
        let _ = write!(
            o,
            r#"<polyline class="series{}" data-series="{}" data-points="{}" data-color="{}" data-dash="{}" fill="none" stroke="{}" stroke-width="1.8"{} points="{}"><title>{} (last {})</title></polyline>"#,
            if s.dashed { " dashed" } else { "" },
            esc(&s.name),
            pts.len(),
            esc(color),
            esc(dash),
            esc(color),
            if dash.is_empty() {
                String::new()
            } else {
                format!(r#" stroke-dasharray="{}""#, esc(dash))
            },
            pts.join(" "),
            esc(&s.name),
            num(last)
        );
    }
    o.push_str("</svg><div class=\"legend\">");
    for (k, s) in series.iter().enumerate() {
        let (color, dash) = if s.dashed {
            ("#555555", "6 4")
        } else {
            style(k)
        };
        let last = s.points.last().map(|p| p.1).unwrap_or(f64::NAN);
        let _ = write!(
            o,
            r#"<span class="key">{}{} <b>{}</b></span>"#,
            swatch(color, dash),
            esc(&s.name),
            num(last)
        );
    }
    o.push_str("</div></figure>");
    o
}

/// The flown track, (longitude, latitude) in degrees, drawn to scale in metres east/north of
/// the first point, with start and end marked and a scale bar. No tiles, no network.
pub(crate) fn svg_map(track: &[(f64, f64)]) -> String {
    let mut o = String::new();
    let _ = write!(
        o,
        r#"<figure class="map" id="map" data-points="{}"><figcaption>Flown track (from the records' positions; north up, to scale)</figcaption>"#,
        track.len()
    );
    let Some(&(lon0, lat0)) = track.first() else {
        o.push_str(r#"<p class="no-data">no positions in this log (simulated runs have none)</p></figure>"#);
        return o;
    };
    let k_lat = 110_540.0;
    let k_lon = 111_320.0 * lat0.to_radians().cos();
    let xy: Vec<(f64, f64)> = track
        .iter()
        .map(|&(lon, lat)| ((lon - lon0) * k_lon, (lat - lat0) * k_lat))
        .collect();
    let (mut x0, mut x1, mut y0, mut y1) = (0f64, 0f64, 0f64, 0f64);
    for &(x, y) in &xy {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    let span = (x1 - x0).max(y1 - y0).max(10.0);
    let (size, pad) = (520.0, 24.0);
    let scale = (size - 2.0 * pad) / span;
    let px = |x: f64| pad + (x - x0) * scale;
    let py = |y: f64| size - pad - (y - y0) * scale;
    let pts: Vec<String> = xy
        .iter()
        .map(|&(x, y)| format!("{:.1},{:.1}", px(x), py(y)))
        .collect();
    let _ = write!(
        o,
        r##"<svg viewBox="0 0 {size} {size}" width="{size}" xmlns="http://www.w3.org/2000/svg" role="img" aria-label="flown track"><rect x="0" y="0" width="{size}" height="{size}" fill="#fbfcfd"/><polyline class="track" fill="none" stroke="#4477aa" stroke-width="2" points="{}"/>"##,
        pts.join(" ")
    );
    let (sx, sy) = xy[0];
    let (ex, ey) = *xy.last().expect("non-empty");
    let _ = write!(
        o,
        r##"<circle class="start" cx="{:.1}" cy="{:.1}" r="6" fill="#228833"><title>start</title></circle><rect class="end" x="{:.1}" y="{:.1}" width="10" height="10" fill="#ee6677"><title>end</title></rect>"##,
        px(sx),
        py(sy),
        px(ex) - 5.0,
        py(ey) - 5.0
    );
    // Scale bar, bottom right: the largest 1, 2 or 5 times a power of ten within a quarter of
    // the span.
    let quarter = span / 4.0;
    let mag = 10f64.powf(quarter.log10().floor());
    let bar = [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|b| *b <= quarter)
        .unwrap_or(mag);
    let (bx1, by) = (size - pad, size - 8.0);
    let bx0 = bx1 - bar * scale;
    let _ = write!(
        o,
        r##"<line class="scale" x1="{bx0:.1}" x2="{bx1:.1}" y1="{by:.1}" y2="{by:.1}" stroke="#333" stroke-width="2"/><text class="tick" x="{bx1:.1}" y="{:.1}" text-anchor="end">{} m</text><text class="tick" x="{:.1}" y="16" text-anchor="end">N ↑</text></svg>"##,
        by - 5.0,
        num(bar),
        size - 8.0
    );
    let _ = write!(
        o,
        "<p class=\"map-note\">extent {} m east × {} m north; start ● end ■</p></figure>",
        num(x1 - x0),
        num(y1 - y0)
    );
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimator_holds_a_bounded_number_of_points_and_the_last() {
        let mut d = Decimator::default();
        for i in 0..1_000_000 {
            d.push(i as f64, (i % 7) as f64);
        }
        let p = d.points();
        assert!(p.len() <= MAX_POINTS + 1, "{}", p.len());
        assert!(p.len() >= MAX_POINTS / 2);
        assert_eq!(p.last(), Some(&(999_999.0, (999_999 % 7) as f64)));
        assert_eq!(p[0], (0.0, 0.0));
    }

    #[test]
    fn twenty_lines_get_twenty_distinct_styles() {
        let styles: std::collections::BTreeSet<_> = (0..48).map(style).collect();
        assert_eq!(styles.len(), 48);
        let colours: std::collections::BTreeSet<_> = PALETTE.iter().collect();
        assert_eq!(colours.len(), PALETTE.len());
    }

    #[test]
    fn map_draws_the_track_north_up() {
        // Start, 100 m north, then 100 m east of that.
        let t = [
            (8.0, 47.0),
            (8.0, 47.0 + 100.0 / 110_540.0),
            (
                8.0 + 100.0 / (111_320.0 * 47f64.to_radians().cos()),
                47.0 + 100.0 / 110_540.0,
            ),
        ];
        let svg = svg_map(&t);
        assert!(svg.contains(r#"data-points="3""#));
        let pts: Vec<(f64, f64)> = svg
            .split("class=\"track\"")
            .nth(1)
            .unwrap()
            .split("points=\"")
            .nth(1)
            .unwrap()
            .split('"')
            .next()
            .unwrap()
            .split(' ')
            .map(|p| {
                let (x, y) = p.split_once(',').unwrap();
                (x.parse().unwrap(), y.parse().unwrap())
            })
            .collect();
        assert!(pts[1].1 < pts[0].1, "north is up: {pts:?}");
        assert!((pts[1].0 - pts[0].0).abs() < 0.5);
        assert!(pts[2].0 > pts[1].0, "east is right: {pts:?}");
        assert!(
            ((pts[2].0 - pts[1].0) - (pts[0].1 - pts[1].1)).abs() < 1.0,
            "to scale"
        );
    }
}
