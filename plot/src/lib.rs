//! # hopper-plot: the hopper's trajectory plots
//!
//! Trajectory plots (PNG), laid out like the thesis's Figure 4.7/4.8:
//! hopping height, actuator position and total energy over time
//! ([`hop_plot`]), of trajectory [`Sample`]s. `hopper-sim run` (the
//! simulator, `hal-sim`, re-exports this crate as `hal_sim::plot`) and
//! `hopper-link record` (the robot's telemetry) draw the same plot, so the
//! host client needs no simulator for it.
//!
//! Also the project's plotting helpers the simulator's figures and the
//! link's capture plot share: the font ([`ensure_font`]), legends
//! ([`legend`], [`side_legend`]), the colour map ([`viridis`],
//! [`colour_strip`]) and one figure as PNG + SVG ([`png_and_svg`]).

mod sample;

pub use sample::{Phase, Sample};

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;
use std::sync::OnceLock;

/// TrueType fonts tried in order (Debian's fonts-dejavu-core is on the
/// project's machines; the others cover common distributions).
const FONT_CANDIDATES: [&str; 4] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
];

/// A chart on `panel` against time: `0..t_hi` s across, `lo..hi` (padded
/// by a tenth, at least 1e-3) up, labelled `label`, its mesh drawn (the
/// planar runner's plots stack these, one quantity a panel).
pub fn time_chart<'a, DB: DrawingBackend>(
    panel: &'a DrawingArea<DB, plotters::coord::Shift>,
    t_hi: f64,
    lo: f64,
    hi: f64,
    label: &str,
) -> Result<
    ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    Box<dyn std::error::Error>,
>
where
    DB::ErrorType: 'static,
{
    let pad = ((hi - lo) * 0.1).max(1e-3);
    let mut c = ChartBuilder::on(panel)
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..t_hi, (lo - pad)..(hi + pad))?;
    c.configure_mesh().x_desc("time [s]").y_desc(label).draw()?;
    Ok(c)
}

/// A grey dashed line across a [`time_chart`] (to `t_hi`) at each of
/// `levels`: a bound or a target.
pub fn dashed_levels<DB: DrawingBackend>(
    c: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    t_hi: f64,
    levels: &[f64],
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let grey = RGBColor(120, 120, 120);
    for &y in levels {
        c.draw_series(DashedLineSeries::new(
            [(0.0, y), (t_hi, y)],
            6,
            4,
            grey.stroke_width(1),
        ))?;
    }
    Ok(())
}

/// The least and the greatest of `values` (`(inf, -inf)` when empty).
pub fn extent(values: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    (
        values.clone().fold(f64::INFINITY, f64::min),
        values.fold(f64::NEG_INFINITY, f64::max),
    )
}

/// The project's legend: at `position`, on a white 80% background with a
/// black border.
pub fn legend<'a, DB, CT>(
    c: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend + 'a,
    CT: plotters::coord::CoordTranslate,
{
    c.configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
}

/// A legend entry for hollow markers (drawn elsewhere): a hollow black
/// circle and `label`.
pub fn hollow_marker_key<'a, DB>(
    c: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    label: &str,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend + 'a,
{
    c.draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
        .label(label)
        .legend(|(x, y)| Circle::new((x + 10, y), 4, BLACK.stroke_width(1)));
    Ok(())
}

/// Load a system font once and register it as "sans-serif" for plotters'
/// pure-Rust text renderer (no fontconfig needed at build time).
pub fn ensure_font() -> Result<(), String> {
    static FONT: OnceLock<Result<(), String>> = OnceLock::new();
    FONT.get_or_init(|| {
        let env = std::env::var("HOPPER_SIM_FONT").ok();
        let candidates = env.iter().map(String::as_str).chain(FONT_CANDIDATES);
        for path in candidates {
            if let Ok(bytes) = std::fs::read(path) {
                // Fonts live for the whole process; leaking one buffer is the
                // 'static lifetime plotters asks for.
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                if plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).is_ok() {
                    return Ok(());
                }
            }
        }
        Err(format!(
            "no TrueType font for plot labels: install fonts-dejavu-core or set HOPPER_SIM_FONT to a .ttf file (tried {FONT_CANDIDATES:?})"
        ))
    })
    .clone()
}

/// What a figure's drawing function returns.
pub type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// One figure as `NAME.png` and `NAME.svg` in `dir` (the simulator's
/// staging directory, `hal_sim::out_dir::write_whole`), `size` pixels: the same drawing,
/// given once per backend (`svg`, `png`); `what` names it in errors.
/// Returns the two file names.
pub fn png_and_svg(
    dir: &Path,
    name: &str,
    size: (u32, u32),
    what: &str,
    svg: impl FnOnce(DrawingArea<SVGBackend<'_>, plotters::coord::Shift>) -> DrawResult,
    png: impl FnOnce(DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>) -> DrawResult,
) -> Result<Vec<String>, String> {
    let (svg_name, png_name) = (format!("{name}.svg"), format!("{name}.png"));
    let mut text = String::new();
    svg(SVGBackend::with_string(&mut text, size).into_drawing_area())
        .map_err(|e| format!("cannot draw {what}: {e}"))?;
    std::fs::write(dir.join(&svg_name), &text)
        .map_err(|e| format!("cannot write {svg_name}: {e}"))?;
    png(BitMapBackend::new(&dir.join(&png_name), size).into_drawing_area())
        .map_err(|e| format!("cannot draw {what}: {e}"))?;
    Ok(vec![png_name, svg_name])
}

type Series<'a> = (&'a str, &'a str, fn(&Sample) -> f64);

/// The winding temperatures the motor's protection acts at, C, drawn on
/// the hop plot's temperature panel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeatLevels {
    /// Derating starts.
    pub derate_c: f64,
    /// The overtemperature fault latches.
    pub trip_c: f64,
    /// Whether the protection acted (off: the levels are where it would
    /// have).
    pub protect: bool,
}

/// How a legend entry beside a chart is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LegendKey {
    /// A solid line of this colour.
    Line(RGBColor),
    /// A dashed line.
    Dashed(RGBColor),
    /// A filled box (a shaded span).
    Fill(RGBColor),
}

/// Width of a legend column beside a chart ([`side_legend`]), px.
pub const SIDE_LEGEND_PX: u32 = 190;

/// The viridis colour map at `t` in 0..=1 (plotters' `ViridisRGB`).
pub fn viridis(t: f64) -> RGBColor {
    // plotters clamps into 0..=1 but turns a NaN into an index and panics:
    // a point whose value cannot be normalised gets the low end instead.
    let t = if t.is_finite() { t } else { 0.0 };
    ViridisRGB::get_color(t)
}

/// A colour bar's strip: the viridis scale from `lo` to `hi` in 100 bands
/// across a chart whose x runs over 0..1 (its y axis is the scale's).
pub fn colour_strip<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    lo: f64,
    hi: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    const STEPS: usize = 100;
    chart.draw_series((0..STEPS).map(|k| {
        let a = lo + (hi - lo) * k as f64 / STEPS as f64;
        let b = lo + (hi - lo) * (k + 1) as f64 / STEPS as f64;
        Rectangle::new(
            [(0.0, a), (1.0, b)],
            viridis(k as f64 / STEPS as f64).filled(),
        )
    }))?;
    Ok(())
}

/// Draws `entries` as a legend in `area`, a column beside a chart, so the
/// legend never covers data.
pub fn side_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    entries: &[(String, LegendKey)],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let style = ("sans-serif", 14).into_font().color(&BLACK);
    for (k, (label, key)) in entries.iter().enumerate() {
        let y = 40 + 22 * k as i32;
        match key {
            LegendKey::Line(c) => {
                area.draw(&PathElement::new(vec![(4, y), (26, y)], c.stroke_width(2)))?
            }
            LegendKey::Dashed(c) => {
                area.draw(&PathElement::new(vec![(4, y), (12, y)], c.stroke_width(2)))?;
                area.draw(&PathElement::new(vec![(18, y), (26, y)], c.stroke_width(2)))?;
            }
            LegendKey::Fill(c) => {
                area.draw(&Rectangle::new([(4, y - 6), (26, y + 6)], c.filled()))?
            }
        }
        area.draw(&Text::new(label.clone(), (32, y - 8), style.clone()))?;
    }
    Ok(())
}

/// Draw toe height (cm), actuator position (mm) and total energy (J) against
/// time into a PNG at `path`; `target_apex_m` adds the apex target as a
/// dashed line on the height panel.
pub fn hop_plot(
    samples: &[Sample],
    title: &str,
    target_apex_m: Option<f64>,
    path: &Path,
) -> Result<(), String> {
    hop_plot_with_heat(samples, title, target_apex_m, None, path)
}

/// [`hop_plot`] with a target that changed: `targets` are (from time, s;
/// target apex, m), each drawn until the next.
pub fn hop_plot_targets(
    samples: &[Sample],
    title: &str,
    targets: &[(f64, f64)],
    path: &Path,
) -> Result<(), String> {
    draw(samples, title, targets, None, path)
}

/// [`hop_plot`], and when the samples carry the firmware's winding
/// temperature a fourth panel with it and the protection's `heat` levels.
/// Legends sit in a column right of the panels, clear of the data.
pub fn hop_plot_with_heat(
    samples: &[Sample],
    title: &str,
    target_apex_m: Option<f64>,
    heat: Option<HeatLevels>,
    path: &Path,
) -> Result<(), String> {
    let targets: Vec<(f64, f64)> = target_apex_m.map(|t| (0.0, t)).into_iter().collect();
    draw(samples, title, &targets, heat, path)
}

fn draw(
    samples: &[Sample],
    title: &str,
    targets: &[(f64, f64)],
    heat: Option<HeatLevels>,
    path: &Path,
) -> Result<(), String> {
    if samples.len() < 2 {
        return Err("not enough samples to plot (is the sample rate 0?)".into());
    }
    ensure_font()?;
    // Each panel with its horizontal reference lines: (from, to time, s;
    // value, label, colour); an empty label adds no legend entry.
    type Levels = Vec<(f64, f64, f64, String, RGBColor)>;
    let cm: Vec<String> = targets
        .iter()
        .map(|(_, t)| format!("{:.1}", t * 100.0))
        .collect();
    let label = match &cm[..] {
        [one] => format!("target apex {one} cm"),
        more => format!("target apex {} cm", more.join(", ")),
    };
    let target: Levels = targets
        .iter()
        .enumerate()
        .map(|(i, &(from, t))| {
            let to = targets.get(i + 1).map_or(f64::INFINITY, |n| n.0);
            (
                from,
                to,
                t * 100.0,
                if i == 0 { label.clone() } else { String::new() },
                RED,
            )
        })
        .collect();
    let mut panels: Vec<(Series, Levels)> = vec![
        (
            ("Hopping height", "toe height [cm]", |s| {
                s.toe_height_m * 100.0
            }),
            target,
        ),
        (
            ("Actuator position", "nut p [mm]", |s| s.p_m * 1000.0),
            Vec::new(),
        ),
        (("Total energy", "energy [J]", |s| s.energy_j), Vec::new()),
    ];
    if samples.iter().all(|s| s.winding_c.is_some()) {
        let levels = heat
            .map(|h| {
                let would = if h.protect { "" } else { " (off)" };
                let all = (f64::NEG_INFINITY, f64::INFINITY);
                vec![
                    (
                        all.0,
                        all.1,
                        h.derate_c,
                        format!("derating {:.0} C{would}", h.derate_c),
                        RGBColor(230, 140, 0),
                    ),
                    (
                        all.0,
                        all.1,
                        h.trip_c,
                        format!("trip {:.0} C{would}", h.trip_c),
                        RED,
                    ),
                ]
            })
            .unwrap_or_default();
        panels.push((
            ("Motor winding (firmware estimate)", "winding [C]", |s| {
                s.winding_c.unwrap_or(f64::NAN)
            }),
            levels,
        ));
    }
    let height = 40 + 290 * panels.len() as u32;
    let root = BitMapBackend::new(path, (1100, height)).into_drawing_area();
    let res = (|| -> Result<(), Box<dyn std::error::Error>> {
        root.fill(&WHITE)?;
        let (head, body) = root.split_vertically(40);
        head.titled(title, ("sans-serif", 22))?;
        let t_end = samples.last().map(|s| s.t_s).unwrap_or(1.0);
        let n = panels.len();
        for (area, ((name, ylabel, get), levels)) in body.split_evenly((n, 1)).iter().zip(panels) {
            let (area, key) = area.split_horizontally(1100 - SIDE_LEGEND_PX);
            let mut entries = vec![(ylabel.to_string(), LegendKey::Line(BLUE))];
            let (mut lo, mut hi) =
                extent(samples.iter().map(get).chain(levels.iter().map(|l| l.2)));
            let pad = ((hi - lo) * 0.05).max(0.5);
            lo -= pad;
            hi += pad;
            let mut chart = ChartBuilder::on(&area)
                .caption(name, ("sans-serif", 18))
                .margin(8)
                .x_label_area_size(36)
                .y_label_area_size(70)
                .build_cartesian_2d(0.0..t_end, lo..hi)?;
            chart
                .configure_mesh()
                .x_desc("time [s]")
                .y_desc(ylabel)
                .light_line_style(WHITE.mix(0.0))
                .draw()?;
            chart.draw_series(LineSeries::new(
                samples.iter().map(|s| (s.t_s, get(s))),
                BLUE.stroke_width(2),
            ))?;
            for (from, to, v, label, colour) in levels {
                let (from, to) = (from.max(0.0), to.min(t_end));
                if from < to {
                    chart.draw_series(DashedLineSeries::new(
                        [(from, v), (to, v)],
                        8,
                        6,
                        colour.stroke_width(2),
                    ))?;
                }
                if !label.is_empty() {
                    entries.push((label, LegendKey::Dashed(colour)));
                }
            }
            side_legend(&key, &entries)?;
        }
        root.present()?;
        Ok(())
    })();
    res.map_err(|e| format!("cannot draw plot {}: {e}", path.display()))
}
