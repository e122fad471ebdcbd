//! The run's figure, like the seed paper's Figure 4: obstacles, the detection radius,
//! planned paths at several replans, and the driven path with the vehicle's footprint,
//! as SVG and PNG.

use std::path::Path;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::scenario::{Obstacle, Scenario};
use crate::vehicle::VehicleState;
use crate::world::position_at;

/// The font the figure's text is drawn with (Debian package fonts-dejavu-core).
pub const FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

/// Why a figure could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("reading the font {path} (install fonts-dejavu-core): {source}")]
    Font {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("the font {0} is not a usable TrueType font")]
    BadFont(String),
    #[error("drawing {path}: {message}")]
    Draw { path: String, message: String },
}

/// A planned path at one replanning.
#[derive(Clone, Debug)]
pub struct PlannedPath {
    pub time: f64,
    pub points: Vec<[f64; 2]>,
    /// Made by the manoeuvre planner: its backward spans and cusps.
    pub manoeuvre: Option<ugv_controller::guidance::ManoeuvreRecord>,
}

/// What the figure shows.
#[derive(Clone, Debug)]
pub struct Figure<'a> {
    pub title: String,
    pub scenario: &'a Scenario,
    /// The driven states, in time order, with their times.
    pub driven: &'a [(f64, VehicleState)],
    pub plans: &'a [PlannedPath],
    /// The controller's detection radius around the vehicle, metres.
    pub detection_radius: f64,
    /// Seconds between drawn footprints.
    pub footprint_every: f64,
}

fn circle_points(x: f64, y: f64, r: f64) -> Vec<(f64, f64)> {
    (0..=72)
        .map(|i| {
            let a = f64::from(i) / 72.0 * std::f64::consts::TAU;
            (x + r * a.cos(), y + r * a.sin())
        })
        .collect()
}

fn rect_points(cx: f64, cy: f64, len: f64, width: f64, heading: f64) -> Vec<(f64, f64)> {
    let (c, s) = (heading.cos(), heading.sin());
    [
        (-1.0, -1.0),
        (1.0, -1.0),
        (1.0, 1.0),
        (-1.0, 1.0),
        (-1.0, -1.0),
    ]
    .iter()
    .map(|(a, b)| {
        let (dx, dy) = (a * len / 2.0, b * width / 2.0);
        (cx + dx * c - dy * s, cy + dx * s + dy * c)
    })
    .collect()
}

/// Outlines of an obstacle at time `t`.
fn obstacle_shapes(o: &Obstacle, t: f64) -> Vec<Vec<(f64, f64)>> {
    match o {
        Obstacle::Circle {
            x,
            y,
            radius,
            motion,
        } => {
            let (px, py) = position_at(*x, *y, motion, t);
            vec![circle_points(px, py, *radius)]
        }
        Obstacle::Box {
            x,
            y,
            length,
            width,
            heading_deg,
            motion,
        } => {
            let (px, py) = position_at(*x, *y, motion, t);
            vec![rect_points(
                px,
                py,
                *length,
                *width,
                heading_deg.to_radians(),
            )]
        }
        Obstacle::Wall { points, thickness } => points
            .windows(2)
            .map(|w| {
                let (dx, dy) = (w[1][0] - w[0][0], w[1][1] - w[0][1]);
                rect_points(
                    (w[0][0] + w[1][0]) / 2.0,
                    (w[0][1] + w[1][1]) / 2.0,
                    dx.hypot(dy),
                    *thickness,
                    dy.atan2(dx),
                )
            })
            .collect(),
    }
}

/// The plotted area: everything, padded, with equal scales.
fn bounds(fig: &Figure<'_>) -> (f64, f64, f64, f64) {
    let sc = fig.scenario;
    let mut xs = vec![sc.start.x, sc.goal.x];
    let mut ys = vec![sc.start.y, sc.goal.y];
    for w in &sc.waypoints {
        xs.push(w.x);
        ys.push(w.y);
    }
    for (_, s) in fig.driven {
        xs.push(s.x);
        ys.push(s.y);
    }
    for o in &sc.obstacles {
        for shape in obstacle_shapes(o, 0.0) {
            for (x, y) in shape {
                xs.push(x);
                ys.push(y);
            }
        }
    }
    let (lo_x, hi_x) = xs
        .iter()
        .fold((f64::MAX, f64::MIN), |a, v| (a.0.min(*v), a.1.max(*v)));
    let (lo_y, hi_y) = ys
        .iter()
        .fold((f64::MAX, f64::MIN), |a, v| (a.0.min(*v), a.1.max(*v)));
    let pad = 4.0;
    (lo_x - pad, hi_x + pad, lo_y - pad, hi_y + pad)
}

/// Manoeuvres shown at most, spread over the run.
const MANOEUVRES_SHOWN: usize = 12;

/// The manoeuvres planned (each new one, at most [`MANOEUVRES_SHOWN`]): forward
/// segments in orange, backward ones in magenta, each cusp a cross.
fn draw_manoeuvres<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    plans: &[PlannedPath],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let new: Vec<(&PlannedPath, &ugv_controller::guidance::ManoeuvreRecord)> = plans
        .iter()
        .filter_map(|p| p.manoeuvre.as_ref().map(|m| (p, m)))
        .filter(|(_, m)| m.expansions > 0 && !m.failed)
        .collect();
    let forward = RGBColor(230, 120, 20);
    let backward = RGBColor(200, 30, 160);
    let step = new.len().div_ceil(MANOEUVRES_SHOWN).max(1);
    for (k, (p, m)) in new.iter().step_by(step).enumerate() {
        let all = ugv_controller::record::manoeuvre_spans(p.points.len(), &m.reverse);
        for (lo, hi, fwd) in all {
            // Each span joined to the next point, so the path has no gaps.
            let end = (hi + 1).min(p.points.len());
            let colour = if fwd { forward } else { backward };
            let series = chart.draw_series(LineSeries::new(
                p.points[lo..end].iter().map(|q| (q[0], q[1])),
                colour.mix(0.8).stroke_width(2),
            ))?;
            if k == 0 {
                let label = if fwd {
                    "manoeuvre forward"
                } else {
                    "manoeuvre backward"
                };
                series
                    .label(label)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], colour));
            }
        }
        chart.draw_series(
            m.cusps
                .iter()
                .map(|c| Cross::new((c[0], c[1]), 5, backward.stroke_width(2))),
        )?;
    }
    Ok(())
}

/// The figure's chart: x East and y North, metres.
type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A drawing error as the message [`PlotError::Draw`] carries.
fn drawing_error<E: std::error::Error + Send + Sync>(err: DrawingAreaErrorKind<E>) -> String {
    err.to_string()
}

/// The whole figure on `root`, within bounds `b`: the axes, then obstacles, plans,
/// the driven path, the route, start and goal, and the legend.
fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    fig: &Figure<'_>,
    b: (f64, f64, f64, f64),
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(drawing_error)?;
    let mut chart = ChartBuilder::on(root)
        .caption(&fig.title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(b.0..b.1, b.2..b.3)
        .map_err(drawing_error)?;
    chart
        .configure_mesh()
        .x_desc("x (East), m")
        .y_desc("y (North), m")
        .light_line_style(RGBColor(235, 235, 235))
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(drawing_error)?;
    draw_obstacles(&mut chart, fig)?;
    draw_plans(&mut chart, fig)?;
    draw_manoeuvres(&mut chart, fig.plans).map_err(drawing_error)?;
    draw_driven(&mut chart, fig)?;
    draw_route(&mut chart, fig.scenario)?;
    draw_start_and_goal(&mut chart, fig.scenario)?;
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .label_font(("sans-serif", 13))
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(drawing_error)?;
    root.present().map_err(drawing_error)?;
    Ok(())
}

/// Obstacles: filled at t = 0; moving ones also outlined where they ended.
fn draw_obstacles<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    fig: &Figure<'_>,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let end_time = fig.driven.last().map_or(0.0, |d| d.0);
    let obstacle_color = RGBColor(200, 80, 60);
    let mut first = true;
    for o in &fig.scenario.obstacles {
        for shape in obstacle_shapes(o, 0.0) {
            let series = chart
                .draw_series(std::iter::once(Polygon::new(
                    shape,
                    obstacle_color.mix(0.55).filled(),
                )))
                .map_err(drawing_error)?;
            if first {
                series.label("obstacle").legend(move |(x, y)| {
                    Rectangle::new(
                        [(x, y - 5), (x + 14, y + 5)],
                        obstacle_color.mix(0.55).filled(),
                    )
                });
                first = false;
            }
        }
        if o.moves() {
            for shape in obstacle_shapes(o, end_time) {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        shape,
                        obstacle_color.stroke_width(1),
                    )))
                    .map_err(drawing_error)?;
            }
        }
    }
    Ok(())
}

/// Planned paths (at most 8, spread over the run) with the detection radius around
/// the vehicle when each was made.
fn draw_plans<DB: DrawingBackend>(chart: &mut Chart<'_, DB>, fig: &Figure<'_>) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let step = (fig.plans.len() / 8).max(1);
    let plan_color = RGBColor(40, 150, 70);
    let radius_color = RGBColor(120, 120, 200);
    let mut labelled = false;
    for p in fig.plans.iter().step_by(step) {
        let series = chart
            .draw_series(LineSeries::new(
                p.points.iter().map(|q| (q[0], q[1])),
                plan_color.mix(0.7).stroke_width(1),
            ))
            .map_err(drawing_error)?;
        if !labelled {
            series
                .label("planned path (replans)")
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], plan_color));
        }
        if let Some((_, s)) = fig.driven.iter().find(|(t, _)| *t >= p.time) {
            let series = chart
                .draw_series(std::iter::once(PathElement::new(
                    circle_points(s.x, s.y, fig.detection_radius),
                    radius_color.mix(0.5).stroke_width(1),
                )))
                .map_err(drawing_error)?;
            if !labelled {
                series
                    .label(format!("detection radius {} m", fig.detection_radius))
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 14, y)], radius_color)
                    });
            }
        }
        labelled = true;
    }
    Ok(())
}

/// The driven path and the vehicle's footprint every `footprint_every` seconds.
fn draw_driven<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    fig: &Figure<'_>,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let path_color = RGBColor(30, 80, 200);
    chart
        .draw_series(LineSeries::new(
            fig.driven.iter().map(|(_, s)| (s.x, s.y)),
            path_color.stroke_width(3),
        ))
        .map_err(drawing_error)?
        .label("driven path (rear axle)")
        .legend(move |(x, y)| {
            PathElement::new(vec![(x, y), (x + 14, y)], path_color.stroke_width(3))
        });
    let vehicle = &fig.scenario.vehicle;
    let mut next = 0.0;
    let mut first_fp = true;
    for (t, s) in fig.driven {
        if *t + 1e-9 < next {
            continue;
        }
        next = t + fig.footprint_every;
        let pts: Vec<(f64, f64)> = s
            .footprint_corners(vehicle)
            .iter()
            .chain(s.footprint_corners(vehicle).first())
            .copied()
            .collect();
        let series = chart
            .draw_series(std::iter::once(PathElement::new(
                pts,
                BLACK.mix(0.6).stroke_width(1),
            )))
            .map_err(drawing_error)?;
        if first_fp {
            series.label("footprint").legend(|(x, y)| {
                Rectangle::new([(x, y - 4), (x + 14, y + 4)], BLACK.stroke_width(1))
            });
            first_fp = false;
        }
    }
    Ok(())
}

/// The route through the waypoints, when the scenario has any.
fn draw_route<DB: DrawingBackend>(chart: &mut Chart<'_, DB>, sc: &Scenario) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    if sc.waypoints.is_empty() {
        return Ok(());
    }
    let route: Vec<(f64, f64)> = std::iter::once((sc.start.x, sc.start.y))
        .chain(sc.waypoints.iter().map(|w| (w.x, w.y)))
        .chain(std::iter::once((sc.goal.x, sc.goal.y)))
        .collect();
    chart
        .draw_series(std::iter::once(PathElement::new(
            route,
            RGBColor(0, 140, 0).mix(0.5).stroke_width(1),
        )))
        .map_err(drawing_error)?
        .label("route")
        .legend(|(x, y)| {
            PathElement::new([(x, y), (x + 14, y)], RGBColor(0, 140, 0).stroke_width(1))
        });
    chart
        .draw_series(
            sc.waypoints
                .iter()
                .map(|w| Circle::new((w.x, w.y), 4, RGBColor(0, 140, 0).stroke_width(1))),
        )
        .map_err(drawing_error)?;
    Ok(())
}

/// The start (black) and the goal (green).
fn draw_start_and_goal<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    sc: &Scenario,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    chart
        .draw_series([
            Circle::new((sc.start.x, sc.start.y), 6, BLACK.filled()),
            Circle::new((sc.goal.x, sc.goal.y), 6, RGBColor(0, 140, 0).filled()),
        ])
        .map_err(drawing_error)?;
    chart
        .draw_series(std::iter::once(Circle::new(
            (sc.goal.x, sc.goal.y),
            1,
            RGBColor(0, 140, 0),
        )))
        .map_err(drawing_error)?
        .label("start (black) / goal (green)")
        .legend(|(x, y)| Circle::new((x + 7, y), 5, RGBColor(0, 140, 0).filled()));
    Ok(())
}

fn register_font() -> Result<(), PlotError> {
    static REGISTERED: std::sync::OnceLock<Result<(), String>> = std::sync::OnceLock::new();
    let result = REGISTERED.get_or_init(|| {
        let bytes = std::fs::read(FONT).map_err(|e| e.to_string())?;
        // plotters keeps the font for the life of the process.
        let leaked: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font("sans-serif", FontStyle::Normal, leaked)
            .map_err(|_| "bad font".to_owned())
    });
    match result {
        Ok(()) => Ok(()),
        Err(m) if m == "bad font" => Err(PlotError::BadFont(FONT.to_owned())),
        Err(m) => Err(PlotError::Font {
            path: FONT.to_owned(),
            source: std::io::Error::other(m.clone()),
        }),
    }
}

/// Draw the figure to an SVG and a PNG file.
pub fn render(fig: &Figure<'_>, svg: &Path, png: &Path) -> Result<(), PlotError> {
    register_font()?;
    let b = bounds(fig);
    let width = 1100u32;
    let height =
        ((f64::from(width) - 62.0) * (b.3 - b.2) / (b.1 - b.0) + 90.0).clamp(300.0, 2400.0) as u32;
    {
        let root = SVGBackend::new(svg, (width, height)).into_drawing_area();
        draw(&root, fig, b).map_err(|message| PlotError::Draw {
            path: svg.display().to_string(),
            message,
        })?;
    }
    let root = BitMapBackend::new(png, (width, height)).into_drawing_area();
    draw(&root, fig, b).map_err(|message| PlotError::Draw {
        path: png.display().to_string(),
        message,
    })
}
