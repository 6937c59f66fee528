//! The figures of a run, as PNG and SVG (plotters):
//!
//! * `trajectory`: the map seen from above — walls, boxes, checkpoints, the
//!   door opening, the paths of the moving objects (the person and the red
//!   object), the robot's path with its start and end, the doorway crossing
//!   and the point where the target was reached (thesis Fig. 4-4);
//! * `motion`: velocity, angular speed and heading against time, with the
//!   doorway and target times and the decision maker's mode changes
//!   (thesis Fig. 4-6).

use crate::DemoError;
use crate::analysis::{Analysis, ModeChange, unwrap_angles};
use crate::scene::Scene;
use crate::truth::TruthRow;
use nerve_plot_font::figure::{DrawResult, Figure, write_png_and_svg};
use nerve_sim::world::Motion;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Every file written by [`write_all`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Figures {
    /// trajectory.png, trajectory.svg, motion.png, motion.svg
    pub files: Vec<PathBuf>,
}

const WALL: RGBColor = RGBColor(90, 90, 90);
const BOX: RGBColor = RGBColor(170, 150, 120);
const ROBOT: RGBColor = RGBColor(30, 90, 200);
const TARGET: RGBColor = RGBColor(210, 30, 30);
const PERSON: RGBColor = RGBColor(120, 80, 160);
const DOOR: RGBColor = RGBColor(20, 150, 60);

/// At most this many points of the robot's path are drawn (the log has 100 per second).
const MAX_POINTS: usize = 4000;

fn thin(rows: &[TruthRow]) -> Vec<&TruthRow> {
    let step = rows.len().div_ceil(MAX_POINTS).max(1);
    let mut v: Vec<&TruthRow> = rows.iter().step_by(step).collect();
    if let (Some(last), Some(kept)) = (rows.last(), v.last())
        && !std::ptr::eq(last, *kept)
    {
        v.push(last);
    }
    v
}

/// Pixel size of the trajectory figure for the scene's aspect ratio.
pub(crate) fn map_size(scene: &Scene) -> (u32, u32, (f64, f64), (f64, f64)) {
    let (lo, hi) = scene.bounds();
    let pad = 0.5;
    // room on the right for the legend, so that it never hides the map
    let legend = ((hi.x - lo.x) * 0.3).max(3.0);
    let (x0, x1, y0, y1) = (lo.x - pad, hi.x + pad + legend, lo.y - pad, hi.y + pad);
    let (w, h) = ((x1 - x0).max(1.0), (y1 - y0).max(1.0));
    let width = 1200u32;
    let plot_w = f64::from(width - 110);
    let height = ((plot_w * h / w) as u32 + 130).clamp(300, 1400);
    (width, height, (x0, x1), (y0, y1))
}

/// The map under a trajectory, seen from above: boxes, walls, door openings,
/// checkpoints (yellow triangles) and targets (red triangles).
pub(crate) fn draw_map<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    scene: &Scene,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    // boxes: filled polygons (worktable, cabinets, clutter)
    for b in &scene.world.boxes {
        let pts: Vec<(f64, f64)> = b.edges.iter().map(|s| (s.a.x, s.a.y)).collect();
        chart.draw_series(std::iter::once(Polygon::new(pts.clone(), BOX.mix(0.8).filled()))).map_err(e)?;
        let mut closed = pts;
        closed.push(closed[0]);
        chart.draw_series(std::iter::once(PathElement::new(closed, WALL.stroke_width(1)))).map_err(e)?;
    }
    // walls
    chart
        .draw_series(
            scene
                .world
                .walls
                .iter()
                .map(|w| PathElement::new(vec![(w.seg.a.x, w.seg.a.y), (w.seg.b.x, w.seg.b.y)], WALL.stroke_width(4))),
        )
        .map_err(e)?
        .label("walls")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], WALL.stroke_width(4)));
    // door openings
    if !scene.doors.is_empty() {
        chart
            .draw_series(scene.doors.iter().map(|d| {
                PathElement::new(
                    vec![(d.opening.a.x, d.opening.a.y), (d.opening.b.x, d.opening.b.y)],
                    DOOR.mix(0.6).stroke_width(3),
                )
            }))
            .map_err(e)?
            .label("door")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], DOOR.mix(0.6).stroke_width(3)));
    }
    // checkpoints
    chart
        .draw_series(scene.world.checkpoints.iter().map(|c| {
            let col = if c.target { TARGET } else { RGBColor(200, 170, 20) };
            TriangleMarker::new((c.position.x, c.position.y), 7, col.filled())
        }))
        .map_err(e)?;
    Ok(())
}

/// A figure with `title` (caption font size `font`), metre axes over
/// `(xr, yr)` and the map drawn: what every trajectory figure starts from.
pub(crate) fn map_chart<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    scene: &Scene,
    title: &str,
    font: u32,
    (xr, yr): ((f64, f64), (f64, f64)),
) -> Result<ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>, String>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", font))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("x (m)")
        .y_desc("y (m)")
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(e)?;
    draw_map(&mut chart, scene)?;
    Ok(chart)
}

fn draw_trajectory<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    scene: &Scene,
    rows: &[TruthRow],
    a: &Analysis,
    title: &str,
    (xr, yr): ((f64, f64), (f64, f64)),
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let mut chart = map_chart(root, scene, title, 20, (xr, yr))?;
    // moving objects: the person's path (and the red object's)
    for (i, o) in scene.world.objects.iter().enumerate() {
        let is_target = scene.target == Some(i);
        let col = if is_target { TARGET } else { PERSON };
        match &o.motion {
            Motion::Path { waypoints, .. } => {
                let pts: Vec<(f64, f64)> = waypoints.iter().map(|p| (p.x, p.y)).collect();
                let s = chart
                    .draw_series(DashedLineSeries::new(pts.clone(), 8, 5, col.mix(0.8).stroke_width(2)))
                    .map_err(e)?;
                if is_target {
                    s.label("person with the red object (path)")
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], col.stroke_width(2)));
                }
                if let (Some(first), Some(last)) = (pts.first(), pts.last()) {
                    chart
                        .draw_series([Circle::new(*first, 5, col.stroke_width(2)), Circle::new(*last, 6, col.filled())])
                        .map_err(e)?;
                }
            }
            Motion::Fixed(p) => {
                chart.draw_series(std::iter::once(Circle::new((p.x, p.y), 6, col.filled()))).map_err(e)?;
            }
        }
    }
    // the robot's path
    let pts: Vec<(f64, f64)> = thin(rows).iter().map(|r| (r.x, r.y)).collect();
    chart
        .draw_series(LineSeries::new(pts.clone(), ROBOT.stroke_width(2)))
        .map_err(e)?
        .label("robot path")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], ROBOT.stroke_width(2)));
    let start = (scene.world.start.x, scene.world.start.y);
    chart
        .draw_series(std::iter::once(Circle::new(start, 8, GREEN.filled())))
        .map_err(e)?
        .label("start")
        .legend(|(x, y)| Circle::new((x + 9, y), 5, GREEN.filled()));
    if let Some(end) = pts.last() {
        chart
            .draw_series(std::iter::once(Cross::new(*end, 8, BLACK.stroke_width(3))))
            .map_err(e)?
            .label("end")
            .legend(|(x, y)| Cross::new((x + 9, y), 5, BLACK.stroke_width(2)));
    }
    let at = |t: f64| rows.iter().find(|r| r.t >= t).map(|r| (r.x, r.y));
    if let Some(p) = a.summary.doorway_time_s.and_then(at) {
        chart
            .draw_series(std::iter::once(Circle::new(p, 7, DOOR.stroke_width(3))))
            .map_err(e)?
            .label("doorway crossed")
            .legend(|(x, y)| Circle::new((x + 9, y), 5, DOOR.stroke_width(2)));
    }
    if let Some(p) = a.summary.target_time_s.and_then(at) {
        chart
            .draw_series(std::iter::once(Circle::new(p, 7, TARGET.stroke_width(3))))
            .map_err(e)?
            .label("target reached")
            .legend(|(x, y)| Circle::new((x + 9, y), 5, TARGET.stroke_width(2)));
    }
    nerve_plot_font::figure::legend(&mut chart, SeriesLabelPosition::UpperRight, 13).map_err(e)?;
    Ok(())
}

fn draw_motion<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    rows: &[TruthRow],
    a: &Analysis,
    modes: &[ModeChange],
    title: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let root = root.titled(title, ("sans-serif", 20)).map_err(e)?;
    let panels = root.split_evenly((3, 1));
    let rows = thin(rows);
    let t_end = rows.last().map_or(1.0, |r| r.t).max(1.0);
    let heading = unwrap_angles(&rows.iter().map(|r| r.theta).collect::<Vec<_>>());
    let series: [(&str, Vec<f64>); 3] = [
        ("(a) velocity (m/s)", rows.iter().map(|r| r.v).collect()),
        ("(b) angular speed (rad/s)", rows.iter().map(|r| r.omega).collect()),
        ("(c) heading (deg, unwrapped)", heading.iter().map(|h| h.to_degrees()).collect()),
    ];
    for (k, (panel, (label, ys))) in panels.iter().zip(series.iter()).enumerate() {
        let (mut lo, mut hi) = ys.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), y| (l.min(*y), h.max(*y)));
        if !lo.is_finite() {
            (lo, hi) = (-1.0, 1.0);
        }
        let pad = ((hi - lo) * 0.08).max(0.05);
        let (lo, hi) = (lo - pad, hi + pad);
        let mut chart = ChartBuilder::on(panel)
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t_end, lo..hi)
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc(if k == 2 { "time (s)" } else { "" })
            .y_desc(*label)
            .light_line_style(RGBColor(238, 238, 238))
            .draw()
            .map_err(e)?;
        // the decision maker's modes: a thin vertical line at each change,
        // labelled in the top panel where there is room for the label
        let mut last_label = f64::NEG_INFINITY;
        for m in modes {
            if let Some(t) = m.t_s.filter(|t| (0.0..=t_end).contains(t)) {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(t, lo), (t, hi)],
                        RGBColor(150, 150, 150).stroke_width(1),
                    )))
                    .map_err(e)?;
                if k == 0 && t - last_label >= t_end * 0.045 {
                    last_label = t;
                    chart
                        .draw_series(std::iter::once(Text::new(
                            m.mode.clone(),
                            (t, hi - (hi - lo) * 0.02),
                            ("sans-serif", 11).into_font().color(&RGBColor(90, 90, 90)),
                        )))
                        .map_err(e)?;
                }
            }
        }
        for (t, col, what) in
            [(a.summary.doorway_time_s, DOOR, "doorway"), (a.summary.target_time_s, TARGET, "target reached")]
        {
            if let Some(t) = t {
                chart
                    .draw_series(DashedLineSeries::new(vec![(t, lo), (t, hi)], 6, 4, col.stroke_width(2)))
                    .map_err(e)?;
                if k == 2 {
                    chart
                        .draw_series(std::iter::once(Text::new(
                            what,
                            (if t > t_end * 0.85 { t - t_end * 0.09 } else { t }, lo + (hi - lo) * 0.1),
                            ("sans-serif", 12).into_font().color(&col),
                        )))
                        .map_err(e)?;
                }
            }
        }
        chart
            .draw_series(LineSeries::new(rows.iter().zip(ys).map(|(r, y)| (r.t, *y)), ROBOT.stroke_width(1)))
            .map_err(e)?;
    }
    Ok(())
}

/// Writes `trajectory.{png,svg}` and `motion.{png,svg}` into `dir`.
pub fn write_all(
    dir: &Path,
    scene: &Scene,
    rows: &[TruthRow],
    analysis: &Analysis,
    modes: &[ModeChange],
    title: &str,
) -> Result<Figures, DemoError> {
    let (w, h, xr, yr) = map_size(scene);
    let s = &analysis.summary;
    let verdict = format!(
        "{title} — doorway {}, target {}, {} collision(s)",
        if s.reached_doorway { "reached" } else { "NOT reached" },
        if s.reached_target { "reached" } else { "NOT reached" },
        s.collisions
    );
    let trajectory = Trajectory { scene, rows, analysis, title: &verdict, range: (xr, yr) };
    let mut files = Vec::from(write_png_and_svg(&dir.join("trajectory"), (w, h), &trajectory)?);
    let mtitle = format!("{title} — velocity, angular speed and heading");
    let motion = MotionFigure { rows, analysis, modes, title: &mtitle };
    files.extend(write_png_and_svg(&dir.join("motion"), (1100, 900), &motion)?);
    Ok(Figures { files })
}

/// The trajectory figure (Fig. 4-4).
struct Trajectory<'a> {
    scene: &'a Scene,
    rows: &'a [TruthRow],
    analysis: &'a Analysis,
    title: &'a str,
    range: ((f64, f64), (f64, f64)),
}

impl Figure for Trajectory<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        Ok(draw_trajectory(root, self.scene, self.rows, self.analysis, self.title, self.range)?)
    }
}

/// The motion figure (Fig. 4-6).
struct MotionFigure<'a> {
    rows: &'a [TruthRow],
    analysis: &'a Analysis,
    modes: &'a [ModeChange],
    title: &'a str,
}

impl Figure for MotionFigure<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        Ok(draw_motion(root, self.rows, self.analysis, self.modes, self.title)?)
    }
}
