//! PNG plots (plotters): `map.png` — top-down, the world's objects and each robot's mapped
//! objects coloured by class, true and estimated trajectories; `ate.png` — team ATE and
//! inter-robot translation errors over time; `bytes.png` — bytes sent by the team over time
//! against raw point-cloud sharing (log scale). Text uses DejaVu Sans from the system
//! (`fonts-dejavu-core`); without it the plots are drawn without text.

use super::Report;
use crate::record::{RunOutcome, SeriesPoint};
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const FONT_PATHS: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
];

/// Registers a system font for plot text once; whether one was found.
fn font() -> bool {
    static FONT: OnceLock<bool> = OnceLock::new();
    *FONT.get_or_init(|| {
        for path in FONT_PATHS {
            if let Ok(bytes) = std::fs::read(path) {
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                if plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).is_ok() {
                    return true;
                }
            }
        }
        tracing::warn!("no DejaVu Sans font found: plots are drawn without text");
        false
    })
}

const ROBOT_COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// A plot that could not be drawn or written, naming its file (plotters' errors are generic
/// over the backend: kept as their text).
#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", path.display())]
pub struct PlotError {
    pub path: PathBuf,
    pub message: String,
}

/// A closure for `map_err` that names `path`.
fn err<E: std::fmt::Display>(path: &Path) -> impl Fn(E) -> PlotError + '_ {
    move |e| PlotError { path: path.to_path_buf(), message: e.to_string() }
}

pub fn draw(outcome: &RunOutcome, report: &Report, dir: &Path) -> Result<(), PlotError> {
    let text = font();
    map(outcome, &dir.join("map.png"), text)?;
    ate(report, &dir.join("ate.png"), text)?;
    bytes(report, &dir.join("bytes.png"), text)
}

fn map(outcome: &RunOutcome, path: &Path, text: bool) -> Result<(), PlotError> {
    let [x0, y0, x1, y1] = outcome.world.bounds;
    let root = BitMapBackend::new(path, (1000, 1000)).into_drawing_area();
    root.fill(&WHITE).map_err(err(path))?;
    let mut builder = ChartBuilder::on(&root);
    builder.margin(20).x_label_area_size(if text { 40 } else { 5 }).y_label_area_size(if text { 50 } else { 5 });
    if text {
        builder.caption("Top-down map: truth (thin) and estimates (thick); objects by class", ("sans-serif", 20));
    }
    let mut chart = builder.build_cartesian_2d(x0..x1, y0..y1).map_err(err(path))?;
    let mut mesh = chart.configure_mesh();
    mesh.disable_mesh();
    if text {
        mesh.x_desc("x (m)").y_desc("y (m)");
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(err(path))?;
    let colour = |label: u16| {
        let [r, g, b] = outcome.world.colours.get(&label).copied().unwrap_or([128, 128, 128]);
        RGBColor(r, g, b)
    };
    // World: objects as hollow squares.
    chart
        .draw_series(outcome.world.objects.iter().map(|o| {
            let (x, y) = (o.centre.x, o.centre.y);
            Rectangle::new([(x - 0.6, y - 0.6), (x + 0.6, y + 0.6)], colour(o.label).stroke_width(1))
        }))
        .map_err(err(path))?;
    let last = outcome.record.last.clone();
    for (k, robot) in outcome.record.robots.iter().enumerate() {
        let c = ROBOT_COLOURS[k % ROBOT_COLOURS.len()];
        let samples = super::figures::trajectory(&last, k, robot);
        chart
            .draw_series(LineSeries::new(
                samples.iter().map(|(_, _, t)| (t.translation.x, t.translation.y)),
                c.mix(0.4).stroke_width(1),
            ))
            .map_err(err(path))?;
        let series = chart
            .draw_series(LineSeries::new(
                samples.iter().map(|(_, e, _)| {
                    let p = robot.truth_from_world * e;
                    (p.translation.x, p.translation.y)
                }),
                c.stroke_width(3),
            ))
            .map_err(err(path))?;
        if text {
            series
                .label(robot.name.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3)));
        }
        // Mapped objects, placed in the truth frame by the robot's start.
        if let Some(Some((summary, _, _))) = last.maps.get(k) {
            chart
                .draw_series(summary.objects.iter().filter(|o| o.confirmed).map(|o| {
                    let p = robot.truth_from_world * o.centroid;
                    Circle::new((p.x, p.y), 3, colour(o.label.0).filled())
                }))
                .map_err(err(path))?;
        }
    }
    if text {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(err(path))?;
    }
    root.present().map_err(err(path))
}

fn ate(report: &Report, path: &Path, text: bool) -> Result<(), PlotError> {
    let root = BitMapBackend::new(path, (1000, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(err(path))?;
    let t_max = time_extent(report);
    let mut y_max: f64 = 0.5;
    for p in &report.series {
        y_max = y_max.max(p.team_ate_rmse_m.unwrap_or(0.0));
        for a in &p.alignments {
            y_max = y_max.max(a.translation_error_m.min(10.0));
        }
    }
    let mut builder = ChartBuilder::on(&root);
    builder.margin(20).x_label_area_size(if text { 40 } else { 5 }).y_label_area_size(if text { 60 } else { 5 });
    if text {
        builder.caption("Team ATE and inter-robot translation error", ("sans-serif", 20));
    }
    let mut chart = builder.build_cartesian_2d(0.0..t_max, 0.0..y_max * 1.1).map_err(err(path))?;
    let mut mesh = chart.configure_mesh();
    if text {
        mesh.x_desc("time (s)").y_desc("error (m)");
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(err(path))?;
    let team = chart
        .draw_series(LineSeries::new(
            report.series.iter().filter_map(|p| p.team_ate_rmse_m.map(|v| (p.t, v))),
            BLACK.stroke_width(3),
        ))
        .map_err(err(path))?;
    if text {
        team.label("team ATE RMSE").legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(3)));
    }
    let mut pairs: Vec<(String, String)> = Vec::new();
    for p in &report.series {
        for a in &p.alignments {
            if !pairs.contains(&(a.local.clone(), a.remote.clone())) {
                pairs.push((a.local.clone(), a.remote.clone()));
            }
        }
    }
    for (k, (local, remote)) in pairs.iter().enumerate() {
        let c = ROBOT_COLOURS[k % ROBOT_COLOURS.len()];
        for (run, points) in aligned_runs(&report.series, local, remote, y_max).into_iter().enumerate() {
            let series = chart.draw_series(LineSeries::new(points, c.stroke_width(1))).map_err(err(path))?;
            if text && run == 0 {
                series
                    .label(format!("{local} ← {remote}"))
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(1)));
            }
        }
    }
    if text {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(err(path))?;
    }
    root.present().map_err(err(path))
}

/// One pair's translation error (clipped at `y_max`) over the stretches it was aligned: a
/// withdrawn alignment leaves a gap, not a line drawn across it.
fn aligned_runs(series: &[SeriesPoint], local: &str, remote: &str, y_max: f64) -> Vec<Vec<(f64, f64)>> {
    let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut open = false;
    for p in series {
        match p.alignments.iter().find(|a| a.local == local && a.remote == remote) {
            Some(a) => {
                let point = (p.t, a.translation_error_m.min(y_max));
                match runs.last_mut() {
                    Some(run) if open => run.push(point),
                    _ => runs.push(vec![point]),
                }
                open = true;
            }
            None => open = false,
        }
    }
    runs
}

/// The time axis: the mission, widened to every sample (a sample off the axis would overflow
/// plotters' pixel arithmetic).
fn time_extent(report: &Report) -> f64 {
    report.series.iter().map(|p| p.t).filter(|t| t.is_finite()).fold(report.sim_s.max(1.0), f64::max)
}

fn bytes(report: &Report, path: &Path, text: bool) -> Result<(), PlotError> {
    let root = BitMapBackend::new(path, (1000, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(err(path))?;
    let t_max = time_extent(report);
    let raw_total = report.point_cloud_raw.bytes_total.max(1) as f64;
    let mut builder = ChartBuilder::on(&root);
    builder.margin(20).x_label_area_size(if text { 40 } else { 5 }).y_label_area_size(if text { 70 } else { 5 });
    if text {
        builder.caption("Bytes sent by the team (log scale)", ("sans-serif", 20));
    }
    let mut chart = builder.build_cartesian_2d(0.0..t_max, (1.0..raw_total * 2.0).log_scale()).map_err(err(path))?;
    let mut mesh = chart.configure_mesh();
    if text {
        mesh.x_desc("time (s)").y_desc("bytes");
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(err(path))?;
    let sgm_colour = ROBOT_COLOURS[0];
    let raw_colour = ROBOT_COLOURS[3];
    let sgm = chart
        .draw_series(LineSeries::new(
            report.series.iter().map(|p| (p.t, (p.bytes_total as f64).max(1.0))),
            sgm_colour.stroke_width(3),
        ))
        .map_err(err(path))?;
    if text {
        sgm.label("SGM").legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], sgm_colour.stroke_width(3)));
    }
    // Raw sharing grows with the frames: linear in time to its total.
    let raw = chart
        .draw_series(LineSeries::new(
            report.series.iter().map(|p| (p.t, (raw_total * p.t / t_max).max(1.0))),
            raw_colour.stroke_width(2),
        ))
        .map_err(err(path))?;
    if text {
        raw.label("raw point clouds")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], raw_colour.stroke_width(2)));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(err(path))?;
    }
    root.present().map_err(err(path))
}

/// One line of a [`lines`] plot.
pub struct Series<'a> {
    pub name: &'a str,
    pub points: Vec<(f64, f64)>,
}

/// A line plot with markers of `series` (the benches' sweeps); `log_y` for byte counts.
pub fn lines(path: &Path, x_desc: &str, y_desc: &str, series: &[Series], log_y: bool) -> Result<(), PlotError> {
    let text = font();
    let all = series.iter().flat_map(|s| s.points.iter());
    let (mut x0, mut x1, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
    let mut y0 = f64::INFINITY;
    for &(x, y) in all {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (0.0, 1.0, 1.0, 1.0);
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    let root = BitMapBackend::new(path, (800, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(err(path))?;
    let mut builder = ChartBuilder::on(&root);
    builder.margin(20).x_label_area_size(if text { 40 } else { 5 }).y_label_area_size(if text { 80 } else { 5 });
    let colour = |k: usize| ROBOT_COLOURS[k % ROBOT_COLOURS.len()];
    macro_rules! draw {
        ($chart:expr) => {{
            let mut chart = $chart;
            let mut mesh = chart.configure_mesh();
            if text {
                mesh.x_desc(x_desc).y_desc(y_desc);
            } else {
                mesh.x_labels(0).y_labels(0);
            }
            mesh.draw().map_err(err(path))?;
            for (k, s) in series.iter().enumerate() {
                let c = colour(k);
                let drawn = chart
                    .draw_series(LineSeries::new(s.points.iter().copied(), c.stroke_width(2)))
                    .map_err(err(path))?;
                if text {
                    drawn
                        .label(s.name)
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
                }
                chart.draw_series(s.points.iter().map(|p| Circle::new(*p, 4, c.filled()))).map_err(err(path))?;
            }
            if text {
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.8))
                    .border_style(BLACK)
                    .draw()
                    .map_err(err(path))?;
            }
        }};
    }
    if log_y {
        let range = (y0.max(1.0) / 2.0)..(y1.max(1.0) * 2.0);
        draw!(builder.build_cartesian_2d(x0..x1, range.log_scale()).map_err(err(path))?);
    } else {
        draw!(builder.build_cartesian_2d(x0..x1, 0.0..(y1 * 1.1).max(1e-3)).map_err(err(path))?);
    }
    root.present().map_err(err(path))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::PairError;

    #[test]
    fn a_plot_that_cannot_be_written_names_its_file() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let path = dir.path().join("missing").join("sweep.png");
        let series = [Series { name: "SGM", points: vec![(1.0, 2.0), (2.0, 3.0)] }];
        let e = lines(&path, "x", "y", &series, false).expect_err("no such directory");
        assert_eq!(e.path, path);
        assert!(e.to_string().starts_with(&path.display().to_string()), "{e}");
        let written = dir.path().join("sweep.png");
        lines(&written, "x", "y", &series, true).expect("a writable file");
        assert!(std::fs::metadata(&written).is_ok_and(|m| m.len() > 0));
    }

    fn point(t: f64, error: Option<f64>) -> SeriesPoint {
        let pair = |e| PairError {
            local: "alpha".into(),
            remote: "bravo".into(),
            translation_error_m: e,
            rotation_error_deg: 0.0,
        };
        SeriesPoint {
            t,
            team_ate_rmse_m: None,
            bytes_total: 0,
            cloud_bytes: 0,
            alignments: error.map(pair).into_iter().collect(),
        }
    }

    /// Aligned, withdrawn, aligned again: two lines with a gap, not one drawn across it.
    #[test]
    fn a_withdrawn_alignment_leaves_a_gap_in_its_line() {
        let errors = [None, Some(0.2), Some(0.3), None, None, Some(9.0), Some(0.1)];
        let series: Vec<_> = errors.iter().enumerate().map(|(k, e)| point(10.0 * k as f64, *e)).collect();
        let runs = aligned_runs(&series, "alpha", "bravo", 5.0);
        assert_eq!(runs, vec![vec![(10.0, 0.2), (20.0, 0.3)], vec![(50.0, 5.0), (60.0, 0.1)]]);
        assert!(aligned_runs(&series, "bravo", "alpha", 5.0).is_empty());
    }
}
