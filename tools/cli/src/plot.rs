//! Evaluation plots: one PNG per evaluation run with the query × map similarity matrix (ground
//! truth and each localizer configuration's predictions drawn over it) next to the
//! precision-recall curves of those configurations.
//!
//! Drawn with `plotters` (bitmap backend, `ab_glyph` text). Text needs a TrueType font, read from
//! [`FONT_PATH`] (Debian package [`FONT_PACKAGE`]); if it is missing, plotting fails with an error
//! naming the package to install. There is no fallback font.

use anyhow::{anyhow, bail, Context, Result};
use plotters::chart::MeshStyle;
use plotters::coord::Shift;
use plotters::element::BitMapElement;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use std::path::Path;
use std::sync::Mutex;

/// The TrueType font used for all text in the plots.
pub const FONT_PATH: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
/// The Debian package that installs [`FONT_PATH`].
pub const FONT_PACKAGE: &str = "fonts-dejavu-core";

/// Marks a query without a prediction in [`Series::predicted`].
pub const NO_PREDICTION: usize = usize::MAX;

/// Upper bound on the number of heat-map cells per axis; larger matrices are max-pooled in blocks.
pub const MAX_HEATMAP_CELLS: usize = 800;

/// Width and height of the written PNG, in pixels.
const IMAGE_SIZE: (u32, u32) = (1700, 850);
/// Width of the left (heat map + colour bar) panel, in pixels.
const LEFT_PANEL_WIDTH: u32 = 920;
/// Width of the colour bar strip at the right of the left panel, in pixels.
const COLORBAR_WIDTH: u32 = 100;
/// Font family name the font is registered under (plotters' `FontFamily::SansSerif`).
pub(crate) const FONT_FAMILY: &str = "sans-serif";

/// Colours of the series, in order (cycled when there are more series).
pub(crate) const SERIES_COLORS: [RGBColor; 6] = [
    RGBColor(228, 26, 28),
    RGBColor(30, 144, 255),
    RGBColor(255, 0, 255),
    RGBColor(255, 127, 0),
    RGBColor(0, 0, 0),
    RGBColor(0, 170, 0),
];
/// Colour of the ground-truth line on the heat map.
const TRUTH_COLOR: RGBColor = RGBColor(255, 255, 255);
/// Colour of heat-map cells that hold no finite similarity value.
const NO_VALUE_COLOR: [u8; 3] = [128, 128, 128];

/// One localizer configuration's results for the plot.
#[derive(Debug, Clone, Copy)]
pub struct Series<'a> {
    /// Name shown in the legends, e.g. `"single-frame"` or `"filter"`.
    pub name: &'a str,
    /// Predicted map index per query frame (length = number of queries, each `< n_map`, or
    /// [`NO_PREDICTION`] for a query without a prediction, which is not drawn).
    pub predicted: &'a [usize],
    /// `(recall, precision)` points with recall ascending, each value in `[0, 1]`; drawn as a
    /// polyline in the given order (may be empty).
    pub precision_recall: &'a [(f64, f64)],
}

/// Writes one PNG with two panels side by side:
///
/// * left: the query × map similarity matrix as a heat map (rows = query frames from the top,
///   columns = map frames; `similarity` is row-major `n_queries × n_map`, values roughly in
///   `[-1, 1]`), colour-scaled (viridis) by the min/max of the displayed values, with a colour
///   bar. The ground truth (`truth[i]` = map index of query `i`) is drawn as a thin white line
///   and each series' predictions as coloured markers, with a legend. Matrices with more than
///   [`MAX_HEATMAP_CELLS`] rows or columns (or more than the plot has pixels) are max-pooled in
///   blocks first, so e.g. 7000 × 7000 plots quickly and the PNG stays small. Non-finite
///   similarity values are ignored (a cell with none finite is grey).
/// * right: the precision-recall curves of each series (axes 0..1, legend, titles).
///
/// `path` must end in `.png`; its directory must exist. Fails with a clear error when the input
/// lengths or indices are inconsistent, a precision/recall value is outside `[0, 1]`, the font
/// ([`FONT_PATH`], Debian package [`FONT_PACKAGE`]) is missing, or the file cannot be written.
pub fn write_evaluation_png(
    path: &Path,
    title: &str,
    similarity: &[f32],
    n_queries: usize,
    n_map: usize,
    truth: Option<&[usize]>,
    series: &[Series<'_>],
) -> Result<()> {
    let figure = Figure {
        similarity,
        n_queries,
        n_map,
        truth,
        series,
    };
    validate(path, &figure)?;
    ensure_font()?;

    let root = BitMapBackend::new(path, IMAGE_SIZE).into_drawing_area();
    draw(&root, title, &figure)
        .map_err(|e| anyhow!("drawing evaluation plot {}: {e}", path.display()))?;
    root.present()
        .map_err(|e| anyhow!("writing evaluation plot {}: {e}", path.display()))?;
    Ok(())
}

/// Writes one PNG with the precision-recall curves of `series` alone (their `predicted` is not
/// drawn): what `topoloc loops --pr-curve` plots over the hints' confidence. `path` must end in
/// `.png` and each point lie in `[0, 1]`; fails like [`write_evaluation_png`].
pub fn write_precision_recall_png(path: &Path, title: &str, series: &[Series<'_>]) -> Result<()> {
    check_png_path(path)?;
    check_precision_recall(series)?;
    ensure_font()?;
    let root = BitMapBackend::new(path, PR_IMAGE_SIZE).into_drawing_area();
    let drawn = root
        .fill(&WHITE)
        .map_err(|e| anyhow!("{e}"))
        .and_then(|()| root.titled(title, font(24)).map_err(|e| anyhow!("{e}")))
        .and_then(|body| draw_precision_recall(&body, series).map_err(|e| anyhow!("{e}")));
    drawn.with_context(|| format!("drawing precision-recall plot {}", path.display()))?;
    root.present()
        .map_err(|e| anyhow!("writing precision-recall plot {}: {e}", path.display()))?;
    Ok(())
}

/// Width and height of [`write_precision_recall_png`]'s PNG, in pixels.
const PR_IMAGE_SIZE: (u32, u32) = (800, 760);

/// What [`write_evaluation_png`] draws (its arguments but the path and title).
#[derive(Clone, Copy)]
struct Figure<'a> {
    similarity: &'a [f32],
    n_queries: usize,
    n_map: usize,
    truth: Option<&'a [usize]>,
    series: &'a [Series<'a>],
}

/// Checks the inputs of [`write_evaluation_png`].
fn validate(path: &Path, figure: &Figure<'_>) -> Result<()> {
    let (n_queries, n_map) = (figure.n_queries, figure.n_map);
    check_png_path(path)?;
    if n_queries == 0 || n_map == 0 {
        bail!("similarity matrix is empty ({n_queries} queries x {n_map} map frames)");
    }
    let expected = n_queries
        .checked_mul(n_map)
        .ok_or_else(|| anyhow!("similarity matrix size {n_queries} x {n_map} overflows"))?;
    if figure.similarity.len() != expected {
        bail!(
            "similarity has {} values, expected n_queries x n_map = {n_queries} x {n_map} = {expected}",
            figure.similarity.len()
        );
    }
    if let Some(truth) = figure.truth {
        check_indices("ground truth", truth, n_queries, n_map, false)?;
    }
    for s in figure.series {
        check_indices(
            &format!("series {:?} predictions", s.name),
            s.predicted,
            n_queries,
            n_map,
            true,
        )?;
    }
    check_precision_recall(figure.series)
}

/// A plot is written as PNG: `path` must end in `.png`.
fn check_png_path(path: &Path) -> Result<()> {
    let is_png = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !is_png {
        bail!("plot path {} must end in .png", path.display());
    }
    Ok(())
}

/// Every series' precision-recall points lie in `[0, 1]`.
fn check_precision_recall(series: &[Series<'_>]) -> Result<()> {
    for s in series {
        for (k, &(recall, precision)) in s.precision_recall.iter().enumerate() {
            let ok = |v: f64| (0.0..=1.0).contains(&v);
            if !ok(recall) || !ok(precision) {
                bail!(
                    "series {:?} precision-recall point {k} (recall {recall}, precision {precision}) is outside [0, 1]",
                    s.name
                );
            }
        }
    }
    Ok(())
}

/// Checks that `indices` has one map index `< n_map` per query (or [`NO_PREDICTION`] when
/// `allow_none`).
fn check_indices(
    what: &str,
    indices: &[usize],
    n_queries: usize,
    n_map: usize,
    allow_none: bool,
) -> Result<()> {
    if indices.len() != n_queries {
        bail!(
            "{what} has {} entries, expected one per query ({n_queries})",
            indices.len()
        );
    }
    let bad = |m: usize| m >= n_map && !(allow_none && m == NO_PREDICTION);
    if let Some((i, &m)) = indices.iter().enumerate().find(|&(_, &m)| bad(m)) {
        bail!("{what}: query {i} has map index {m}, but the map has only {n_map} frames");
    }
    Ok(())
}

/// Registers [`FONT_PATH`] with plotters once per process; errors (naming the Debian package)
/// when the file is missing or unreadable.
pub(crate) fn ensure_font() -> Result<()> {
    static REGISTERED: Mutex<bool> = Mutex::new(false);
    let mut registered = REGISTERED.lock().unwrap_or_else(|e| e.into_inner());
    if *registered {
        return Ok(());
    }
    let bytes = std::fs::read(FONT_PATH).with_context(|| {
        format!(
            "cannot read font {FONT_PATH} needed for evaluation plots; install the Debian package \
             {FONT_PACKAGE} (apt-get install {FONT_PACKAGE}, or run scripts/install-deps.sh)"
        )
    })?;
    // plotters keeps fonts for the life of the process; this runs at most once.
    let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
    register_font(FONT_FAMILY, FontStyle::Normal, bytes).map_err(|_| {
        anyhow!("{FONT_PATH} is not a valid TrueType font (package {FONT_PACKAGE})")
    })?;
    *registered = true;
    Ok(())
}

/// Text style of the given size in the registered font.
pub(crate) fn font(size: u32) -> TextStyle<'static> {
    (FONT_FAMILY, size).into_font().into()
}

/// What the drawing functions return: plotters' errors, boxed.
pub(crate) type DrawResult<T> = std::result::Result<T, Box<dyn std::error::Error + Send + Sync>>;

/// A legend entry's sample: a 20-pixel line in `style` (for `SeriesAnno::legend`).
pub(crate) fn legend_line(
    style: impl Into<ShapeStyle>,
) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    let style = style.into();
    move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style)
}

/// Titles both axes of `mesh` and formats their ticks with `ticks`, in the plots' font sizes.
pub(crate) fn label_axes<'b, X, Y, DB>(
    mesh: &mut MeshStyle<'_, 'b, X, Y, DB>,
    x_desc: &str,
    y_desc: &str,
    ticks: &'b dyn Fn(&f64) -> String,
) where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
    DB: DrawingBackend,
{
    mesh.x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(ticks)
        .y_label_formatter(ticks)
        .label_style(font(14))
        .axis_desc_style(font(16));
}

/// Draws the series labels of `chart` at `position` on a light box with a black border.
pub(crate) fn draw_light_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> DrawResult<()>
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .label_font(font(15))
        .draw()?;
    Ok(())
}

/// Draws the whole figure onto `root`.
fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    figure: &Figure<'_>,
) -> DrawResult<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let body = root.titled(title, font(28))?;
    let (left, right) = body.split_horizontally(LEFT_PANEL_WIDTH);
    draw_heatmap(&left, figure)?;
    draw_precision_recall(&right, figure.series)?;
    Ok(())
}

/// Result of max-pooling the similarity matrix.
struct Pooled {
    /// Cell values, row-major with `cols` cells per row; NaN where a block had no finite value.
    values: Vec<f32>,
    cols: usize,
    /// Block height (query frames per cell row) and width (map frames per cell column).
    block: (usize, usize),
    /// Min and max of the finite cell values (`None` if there are none).
    range: Option<(f32, f32)>,
}

/// Max-pools `similarity` (`n_rows × n_cols`) in blocks so that there are at most `max_rows ×
/// max_cols` cells. Non-finite values are ignored.
fn max_pool(
    similarity: &[f32],
    n_rows: usize,
    n_cols: usize,
    max_rows: usize,
    max_cols: usize,
) -> Pooled {
    let br = n_rows.div_ceil(max_rows.max(1));
    let bc = n_cols.div_ceil(max_cols.max(1));
    let rows = n_rows.div_ceil(br);
    let cols = n_cols.div_ceil(bc);
    let mut values = vec![f32::NEG_INFINITY; rows * cols];
    for (r, row) in similarity.chunks_exact(n_cols).enumerate() {
        let out = &mut values[(r / br) * cols..][..cols];
        for (cell, block) in out.iter_mut().zip(row.chunks(bc)) {
            let m = block.iter().fold(f32::NEG_INFINITY, |a, &v| {
                if v.is_finite() && v > a {
                    v
                } else {
                    a
                }
            });
            if m > *cell {
                *cell = m;
            }
        }
    }
    let mut range: Option<(f32, f32)> = None;
    for v in &mut values {
        if *v == f32::NEG_INFINITY {
            *v = f32::NAN;
        } else {
            range = Some(match range {
                None => (*v, *v),
                Some((lo, hi)) => (lo.min(*v), hi.max(*v)),
            });
        }
    }
    Pooled {
        values,
        cols,
        block: (br, bc),
        range,
    }
}

/// Viridis colour map control points (equally spaced from 0 to 1).
const VIRIDIS: [[f32; 3]; 9] = [
    [68.0, 1.0, 84.0],
    [71.0, 44.0, 122.0],
    [59.0, 81.0, 139.0],
    [44.0, 113.0, 142.0],
    [33.0, 144.0, 141.0],
    [39.0, 173.0, 129.0],
    [92.0, 200.0, 99.0],
    [170.0, 220.0, 50.0],
    [253.0, 231.0, 37.0],
];

/// Viridis colour of `t` in `[0, 1]` (clamped).
fn viridis(t: f32) -> [u8; 3] {
    let x = t.clamp(0.0, 1.0) * (VIRIDIS.len() - 1) as f32;
    let i = (x.floor() as usize).min(VIRIDIS.len() - 2);
    let f = x - i as f32;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    std::array::from_fn(|k| (a[k] + (b[k] - a[k]) * f).round() as u8)
}

/// For each of `pixels` pixels along an axis spanning `n` matrix entries pooled in blocks of
/// `block`, the cell index shown at the pixel's centre.
fn pixel_cells(pixels: usize, n: usize, block: usize) -> Vec<usize> {
    (0..pixels)
        .map(|p| {
            let entry = (((p as f64 + 0.5) * n as f64 / pixels as f64) as usize).min(n - 1);
            entry / block
        })
        .collect()
}

/// Pixels in a drawing area's pixel range (at least 1).
fn pixels(range: &std::ops::Range<i32>) -> usize {
    (range.end - range.start).max(1) as usize
}

/// Draws the heat map panel (with truth, predictions, legend and colour bar) onto `area`.
fn draw_heatmap<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    figure: &Figure<'_>,
) -> DrawResult<()>
where
    DB::ErrorType: 'static,
{
    let Figure {
        similarity,
        n_queries,
        n_map,
        truth,
        series,
    } = *figure;
    let (heat_area, bar_area) = area.split_horizontally(LEFT_PANEL_WIDTH - COLORBAR_WIDTH);
    let mut chart = ChartBuilder::on(&heat_area)
        .caption(
            "similarity (rows: query frames, columns: map frames)",
            font(20),
        )
        .margin(10)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(0f64..n_map as f64, n_queries as f64..0f64)?;
    let integer = |v: &f64| format!("{v:.0}");
    let mut mesh = chart.configure_mesh();
    label_axes(mesh.disable_mesh(), "map frame", "query frame", &integer);
    mesh.draw()?;

    // The matrix, pooled to at most one cell per pixel, rendered pixel by pixel and blitted.
    let (px_range, py_range) = chart.plotting_area().get_pixel_range();
    let (w, h) = (pixels(&px_range), pixels(&py_range));
    let pooled = max_pool(
        similarity,
        n_queries,
        n_map,
        MAX_HEATMAP_CELLS.min(h),
        MAX_HEATMAP_CELLS.min(w),
    );
    let (lo, hi) = match pooled.range {
        Some((lo, hi)) if hi > lo => (lo, hi),
        Some((lo, _)) => (lo, lo + 1.0),
        None => (0.0, 1.0),
    };
    let lut: Vec<[u8; 3]> = (0..256).map(|k| viridis(k as f32 / 255.0)).collect();
    let color_of = |v: f32| -> [u8; 3] {
        if v.is_nan() {
            NO_VALUE_COLOR
        } else {
            lut[(((v - lo) / (hi - lo)) * 255.0).round().clamp(0.0, 255.0) as usize]
        }
    };
    let col_cells = pixel_cells(w, n_map, pooled.block.1);
    let row_cells = pixel_cells(h, n_queries, pooled.block.0);
    let mut buf = Vec::with_capacity(w * h * 3);
    for &r in &row_cells {
        let row = &pooled.values[r * pooled.cols..][..pooled.cols];
        for &c in &col_cells {
            buf.extend_from_slice(&color_of(row[c]));
        }
    }
    let bitmap = BitMapElement::with_owned_buffer((0.0, 0.0), (w as u32, h as u32), buf)
        .ok_or("heat map bitmap buffer has the wrong size")?;
    chart.draw_series(std::iter::once(bitmap))?;

    // Smaller markers when queries are denser than pixel rows, so the diagonal stays readable.
    let (radius, stroke) = if n_queries <= 300 {
        (3, 2)
    } else if n_queries <= h {
        (2, 2)
    } else {
        (1, 1)
    };
    for (k, s) in series.iter().enumerate() {
        let color = SERIES_COLORS[k % SERIES_COLORS.len()];
        let points = s
            .predicted
            .iter()
            .enumerate()
            .filter(|&(_, &m)| m != NO_PREDICTION)
            .map(|(i, &m)| (m as f64 + 0.5, i as f64 + 0.5));
        // Alternate marker shapes so overlapping series stay distinguishable.
        match k % 3 {
            0 => chart
                .draw_series(points.map(|p| Circle::new(p, radius, color.filled())))?
                .label(s.name)
                .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled())),
            1 => chart
                .draw_series(points.map(|p| Cross::new(p, radius + 1, color.stroke_width(stroke))))?
                .label(s.name)
                .legend(move |(x, y)| Cross::new((x + 10, y), 5, color.stroke_width(2))),
            _ => chart
                .draw_series(points.map(|p| TriangleMarker::new(p, radius + 1, color.filled())))?
                .label(s.name)
                .legend(move |(x, y)| TriangleMarker::new((x + 10, y), 5, color.filled())),
        };
    }
    if let Some(truth) = truth {
        // Drawn over the predictions so it stays visible: a polyline through consecutive
        // queries, broken where the true map index jumps (revisits); a query on its own gets a
        // short horizontal tick across its cell.
        let max_step = (n_map / 50).max(1);
        let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
        for (i, &m) in truth.iter().enumerate() {
            let p = (m as f64 + 0.5, i as f64 + 0.5);
            match runs.last_mut() {
                Some(run) if i > 0 && truth[i - 1].abs_diff(m) <= max_step => run.push(p),
                _ => runs.push(vec![p]),
            }
        }
        for run in &mut runs {
            if let [(x, y)] = run[..] {
                *run = vec![(x - 0.5, y), (x + 0.5, y)];
            }
        }
        let style = TRUTH_COLOR.stroke_width(1);
        chart
            .draw_series(runs.into_iter().map(|run| PathElement::new(run, style)))?
            .label("ground truth")
            .legend(legend_line(style));
    }

    if truth.is_some() || !series.is_empty() {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(RGBColor(40, 40, 40).mix(0.8))
            .border_style(WHITE)
            .label_font(font(15).color(&WHITE))
            .draw()?;
    }

    // Colour bar, vertically aligned with the heat map's plotting area.
    let (_, bar_y) = bar_area.get_pixel_range();
    let bar_area = bar_area.margin(
        (py_range.start - bar_y.start).max(0),
        (bar_y.end - py_range.end).max(0),
        5,
        0,
    );
    let mut bar = ChartBuilder::on(&bar_area)
        .right_y_label_area_size(65)
        .build_cartesian_2d(0f64..1f64, lo as f64..hi as f64)?;
    // Values that round to zero print as "0.00", not "-0.00".
    let two_decimals = |v: &f64| format!("{:.2}", if v.abs() < 0.005 { 0.0 } else { *v });
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_label_formatter(&two_decimals)
        .label_style(font(14))
        .draw()?;
    let (bx, by) = bar.plotting_area().get_pixel_range();
    let (bw, bh) = (pixels(&bx), pixels(&by));
    let mut buf = Vec::with_capacity(bw * bh * 3);
    for y in 0..bh {
        let c = viridis(1.0 - (y as f32 + 0.5) / bh as f32);
        for _ in 0..bw {
            buf.extend_from_slice(&c);
        }
    }
    let bitmap = BitMapElement::with_owned_buffer((0.0, hi as f64), (bw as u32, bh as u32), buf)
        .ok_or("colour bar bitmap buffer has the wrong size")?;
    bar.draw_series(std::iter::once(bitmap))?;
    let (br, bc) = pooled.block;
    if br > 1 || bc > 1 {
        let note = format!("max-pooled {br}x{bc}");
        area.draw_text(
            &note,
            &font(13),
            (
                (LEFT_PANEL_WIDTH - COLORBAR_WIDTH) as i32 - 150,
                area.dim_in_pixel().1 as i32 - 22,
            ),
        )?;
    }
    Ok(())
}

/// Draws the precision-recall panel onto `area`.
fn draw_precision_recall<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    series: &[Series<'_>],
) -> DrawResult<()>
where
    DB::ErrorType: 'static,
{
    let mut chart = ChartBuilder::on(area)
        .caption("precision-recall", font(20))
        .margin(10)
        .margin_right(25)
        .x_label_area_size(50)
        .y_label_area_size(60)
        .build_cartesian_2d(0f64..1f64, 0f64..1.02f64)?;
    let one_decimal = |v: &f64| format!("{v:.1}");
    let mut mesh = chart.configure_mesh();
    label_axes(&mut mesh, "recall", "precision", &one_decimal);
    mesh.max_light_lines(1)
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    for (k, s) in series.iter().enumerate() {
        let color = SERIES_COLORS[k % SERIES_COLORS.len()];
        chart
            .draw_series(LineSeries::new(
                s.precision_recall.iter().copied(),
                color.stroke_width(2),
            ))?
            .label(s.name)
            .legend(legend_line(color.stroke_width(2)));
        if s.precision_recall.len() <= 50 {
            chart.draw_series(
                s.precision_recall
                    .iter()
                    .map(|&p| Circle::new(p, 3, color.filled())),
            )?;
        }
    }
    if !series.is_empty() {
        draw_light_legend(&mut chart, SeriesLabelPosition::LowerLeft)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    /// A synthetic `n_q × n_m` similarity matrix with a bright (noisy) diagonal band.
    fn diagonal_matrix(n_q: usize, n_m: usize) -> Vec<f32> {
        let mut s = Vec::with_capacity(n_q * n_m);
        for i in 0..n_q {
            let d = i as f32 * n_m as f32 / n_q as f32;
            for j in 0..n_m {
                let x = (j as f32 - d) / (n_m as f32 / 30.0).max(2.0);
                let noise = (((i * 31 + j * 17) % 97) as f32 / 97.0 - 0.5) * 0.2;
                s.push((-(x * x)).exp() * 1.4 - 0.5 + noise);
            }
        }
        s
    }

    /// `(truth, single-frame predictions, filter predictions, single-frame PR, filter PR)`.
    type Example = (
        Vec<usize>,
        Vec<usize>,
        Vec<usize>,
        Vec<(f64, f64)>,
        Vec<(f64, f64)>,
    );

    /// Ground truth on the diagonal and two prediction series (one with some errors) with PR curves.
    fn example(n_q: usize, n_m: usize) -> Example {
        let truth: Vec<usize> = (0..n_q).map(|i| i * n_m / n_q).collect();
        let single: Vec<usize> = truth
            .iter()
            .enumerate()
            .map(|(i, &t)| if i % 7 == 3 { (t * 13 + 5) % n_m } else { t })
            .collect();
        let filter: Vec<usize> = truth.iter().map(|&t| (t + 1).min(n_m - 1)).collect();
        let pr_single: Vec<(f64, f64)> = (0..=20)
            .map(|k| {
                let r = k as f64 / 20.0;
                (r, 1.0 - 0.5 * r * r)
            })
            .collect();
        let pr_filter: Vec<(f64, f64)> = (0..=20)
            .map(|k| {
                let r = k as f64 / 20.0;
                (r, 1.0 - 0.2 * r.powi(4))
            })
            .collect();
        (truth, single, filter, pr_single, pr_filter)
    }

    /// Reads the PNG back and checks its size and that it is not blank.
    fn check_png(path: &Path) {
        let bytes = std::fs::read(path).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "not a PNG");
        let img = image::open(path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), IMAGE_SIZE);
        let first = *img.get_pixel(0, 0);
        let differing = img.pixels().filter(|&&p| p != first).count();
        assert!(
            differing > 10_000,
            "image looks blank ({differing} non-background pixels)"
        );
        // The heat map contributes the viridis extremes (dark purple and yellow-ish pixels).
        assert!(
            img.pixels()
                .any(|p| p.0[0] < 90 && p.0[1] < 30 && p.0[2] > 60),
            "no dark heat-map cells"
        );
        assert!(
            img.pixels()
                .any(|p| p.0[0] > 200 && p.0[1] > 200 && p.0[2] < 80),
            "no bright heat-map cells"
        );
    }

    /// Writes the example plot of an `n_q × n_m` diagonal matrix to `path`, checks it and copies
    /// it to the file named by the environment variable `sample_var` if set; returns how long
    /// writing the PNG took.
    fn write_example_png(path: &Path, n_q: usize, n_m: usize, sample_var: &str) -> Duration {
        let sim = diagonal_matrix(n_q, n_m);
        let (truth, single, filter, pr_s, pr_f) = example(n_q, n_m);
        let series = [
            Series {
                name: "single-frame",
                predicted: &single,
                precision_recall: &pr_s,
            },
            Series {
                name: "filter",
                predicted: &filter,
                precision_recall: &pr_f,
            },
        ];
        let title = format!("synthetic {n_q} x {n_m}");
        let start = Instant::now();
        write_evaluation_png(path, &title, &sim, n_q, n_m, Some(&truth), &series).unwrap();
        let elapsed = start.elapsed();
        check_png(path);
        if let Ok(dest) = std::env::var(sample_var) {
            std::fs::copy(path, dest).unwrap();
        }
        elapsed
    }

    #[test]
    fn plot_writes_small_png() {
        let dir = tempfile::tempdir().unwrap();
        write_example_png(&dir.path().join("eval.png"), 50, 60, "TOPOLOC_PLOT_SAMPLE");
    }

    #[test]
    fn plot_without_truth_or_series() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bare.PNG");
        let sim = diagonal_matrix(5, 3);
        write_evaluation_png(&path, "bare", &sim, 5, 3, None, &[]).unwrap();
        assert_eq!(
            image::open(&path).unwrap().to_rgb8().dimensions(),
            IMAGE_SIZE
        );
        // A constant matrix and non-finite values are tolerated too.
        let mut flat = vec![0.25f32; 12];
        flat[3] = f32::NAN;
        flat[4] = f32::NEG_INFINITY;
        write_evaluation_png(&path, "flat", &flat, 3, 4, None, &[]).unwrap();
        // Queries without a prediction are allowed (and not drawn).
        let predicted = [1, NO_PREDICTION, 3];
        let series = [Series {
            name: "partial",
            predicted: &predicted,
            precision_recall: &[],
        }];
        write_evaluation_png(&path, "partial", &flat, 3, 4, Some(&[0, 1, 2]), &series).unwrap();
    }

    #[test]
    fn plot_rejects_bad_inputs() {
        let dir = tempfile::tempdir().unwrap();
        let sim = vec![0.0f32; 6];
        let ok_pred = [0usize, 1];
        let pr = [(0.0, 1.0), (1.0, 0.5)];
        let good = Series {
            name: "s",
            predicted: &ok_pred,
            precision_recall: &pr,
        };
        let short = Series {
            predicted: &ok_pred[..1],
            ..good
        };
        let big = Series {
            predicted: &[0, 3],
            ..good
        };
        let bad_pr = Series {
            precision_recall: &[(0.5, 1.5)],
            ..good
        };
        // (similarity, queries, truth, series, expected error); the map has 3 frames.
        type Case<'a> = (
            &'a [f32],
            usize,
            Option<&'a [usize]>,
            &'a [Series<'a>],
            &'a str,
        );
        let cases: [Case; 8] = [
            (&sim[..5], 2, None, &[good], "similarity has 5 values"),
            (&[], 0, None, &[], "empty"),
            (&sim, 2, Some(&[0]), &[good], "ground truth has 1 entries"),
            (&sim, 2, Some(&[0, 3]), &[good], "query 1 has map index 3"),
            (
                &sim,
                2,
                None,
                &[good, short],
                "series \"s\" predictions has 1 entries",
            ),
            (
                &sim,
                2,
                Some(&[0, NO_PREDICTION]),
                &[],
                "query 1 has map index",
            ),
            (
                &sim,
                2,
                None,
                &[big],
                "series \"s\" predictions: query 1 has map index 3",
            ),
            (&sim, 2, None, &[bad_pr], "outside [0, 1]"),
        ];
        let path = dir.path().join("bad.png");
        for (similarity, n_q, truth, series, expected) in cases {
            let result = write_evaluation_png(&path, "t", similarity, n_q, 3, truth, series);
            let e = format!("{:#}", result.unwrap_err());
            assert!(e.contains(expected), "{e}");
        }
        let jpg = write_evaluation_png(&dir.path().join("x.jpg"), "t", &sim, 2, 3, None, &[good]);
        let e = format!("{:#}", jpg.unwrap_err());
        assert!(e.contains("must end in .png"), "{e}");
        assert!(!path.exists(), "nothing is written for invalid input");
    }

    #[test]
    fn plot_max_pool_blocks() {
        // 5 x 7 pooled to at most 2 x 3 cells: blocks of 3 x 3.
        let m: Vec<f32> = (0..35).map(|v| v as f32).collect();
        let p = max_pool(&m, 5, 7, 2, 3);
        assert_eq!((p.values.len() / p.cols, p.cols, p.block), (2, 3, (3, 3)));
        assert_eq!(p.values, vec![16.0, 19.0, 20.0, 30.0, 33.0, 34.0]);
        assert_eq!(p.range, Some((16.0, 34.0)));
    }

    /// Times a 7000 x 7000 plot; run with
    /// `cargo test --release -p topoloc-cli plot -- --ignored --nocapture`.
    #[test]
    #[ignore = "slow in debug builds; a timing check for release builds"]
    fn plot_large_matrix_timing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("large.png");
        let elapsed = write_example_png(&path, 7000, 7000, "TOPOLOC_PLOT_SAMPLE_LARGE");
        let size = std::fs::metadata(&path).unwrap().len();
        println!(
            "7000 x 7000 evaluation plot: {:.3} s, {} KiB",
            elapsed.as_secs_f64(),
            size / 1024
        );
        assert!(elapsed.as_secs_f64() < 2.0, "plot took {elapsed:?}");
    }
}
