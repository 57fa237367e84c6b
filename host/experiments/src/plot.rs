//! SVG plots for the reports, drawn with plotters: one kind of chart (x-y with lines, points and segments)
//! covers every figure the reports need.

use plotters::prelude::*;

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    Line,
    Points,
    /// Consecutive pairs of points as separate segments (error vectors).
    Segments,
}

#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub style: Style,
}

impl Series {
    pub fn new(name: impl Into<String>, style: Style, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
            style,
        }
    }
}

/// A chart: title, axis labels and its series.
#[derive(Clone, Debug)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    /// Same scale on both axes (maps in mm).
    pub equal_axes: bool,
}

impl Chart {
    pub fn new(title: impl Into<String>, x_label: impl Into<String>, y_label: impl Into<String>) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            equal_axes: false,
        }
    }

    pub fn with(mut self, series: Series) -> Self {
        self.series.push(series);
        self
    }

    /// The chart as an SVG document.
    pub fn to_svg(&self) -> Result<String, String> {
        const SIZE: (u32, u32) = (720, 480);
        let finite = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
        let all: Vec<(f64, f64)> = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().filter(finite).copied())
            .collect();
        let (mut x, mut y) = (range(all.iter().map(|p| p.0)), range(all.iter().map(|p| p.1)));
        if self.equal_axes {
            // Plot area is roughly 640 x 400 px: widen the narrower axis so a millimetre is as long on both.
            let aspect = 640.0 / 400.0;
            let (w, h) = (x.1 - x.0, y.1 - y.0);
            if w / h < aspect {
                let grow = (h * aspect - w) / 2.0;
                x = (x.0 - grow, x.1 + grow);
            } else {
                let grow = (w / aspect - h) / 2.0;
                y = (y.0 - grow, y.1 + grow);
            }
        }
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
            root.fill(&WHITE).map_err(|e| e.to_string())?;
            let mut chart = ChartBuilder::on(&root)
                .caption(&self.title, ("sans-serif", 20))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(56)
                .build_cartesian_2d(x.0..x.1, y.0..y.1)
                .map_err(|e| e.to_string())?;
            chart
                .configure_mesh()
                .x_desc(&self.x_label)
                .y_desc(&self.y_label)
                .light_line_style(WHITE.mix(0.0))
                .draw()
                .map_err(|e| e.to_string())?;
            for (index, series) in self.series.iter().enumerate() {
                let colour = Palette99::pick(index).to_rgba();
                let points: Vec<(f64, f64)> = series.points.iter().filter(finite).copied().collect();
                let legend =
                    move |(x, y): (i32, i32)| PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(3));
                let drawn = match series.style {
                    Style::Line => chart.draw_series(LineSeries::new(points, colour.stroke_width(2))),
                    Style::Points => chart.draw_series(points.into_iter().map(|p| Circle::new(p, 3, colour.filled()))),
                    Style::Segments => chart.draw_series(
                        points
                            .chunks_exact(2)
                            .map(|pair| PathElement::new(vec![pair[0], pair[1]], colour.stroke_width(2))),
                    ),
                };
                drawn
                    .map_err(|e| e.to_string())?
                    .label(series.name.as_str())
                    .legend(legend);
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperLeft)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()
                .map_err(|e| e.to_string())?;
            root.present().map_err(|e| e.to_string())?;
        }
        Ok(svg)
    }
}

/// The values' span with a 5 % margin; a unit span around a single value; (0, 1) when there is nothing.
fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    if span <= 0.0 {
        return (lo - 0.5, hi + 0.5);
    }
    (lo - 0.05 * span, hi + 0.05 * span)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_chart_is_an_svg_with_its_title_labels_and_one_mark_per_point() {
        let svg = Chart::new("force against gamma", "gamma", "force (N)")
            .with(Series::new(
                "readings",
                Style::Points,
                vec![(0.0, 1.0), (1.0, 2.0), (2.0, 3.5)],
            ))
            .with(Series::new("fit", Style::Line, vec![(0.0, 1.0), (2.0, 3.5)]))
            .to_svg()
            .unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..80.min(svg.len())]);
        for text in ["force against gamma", "gamma", "force (N)", "readings", "fit"] {
            assert!(svg.contains(text), "{text} missing");
        }
        assert_eq!(svg.matches("<circle").count(), 3);
        // A NaN is left out rather than poisoning the axes.
        let svg = Chart::new("t", "x", "y")
            .with(Series::new(
                "s",
                Style::Points,
                vec![(0.0, 0.0), (f64::NAN, 1.0), (1.0, 1.0)],
            ))
            .to_svg()
            .unwrap();
        assert_eq!(svg.matches("<circle").count(), 2);
    }
}
