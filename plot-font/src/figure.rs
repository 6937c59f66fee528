//! One way to write a figure: [`write_png_and_svg`] (and [`write_png`],
//! [`write_svg`], [`write`]; [`write_png_with`] for a bitmap drawn by a
//! closure) make the backend, register the font ([`crate::register`]),
//! paint the background white, let the [`Figure`] draw, and write the
//! file, so that every figure of nerve (the demos', the calibration's,
//! `nerve plot`'s, the benchmarks') is set up alike and fails alike: with
//! the file's path and plotters' cause.
//!
//! A figure is drawn once per file format, by the same code: [`Figure::draw`]
//! is generic over plotters' backend.
//!
//! ```no_run
//! use nerve_plot_font::figure::{DrawResult, Figure, write_png_and_svg};
//! use plotters::coord::Shift;
//! use plotters::prelude::*;
//!
//! struct Line(Vec<(f64, f64)>);
//!
//! impl Figure for Line {
//!     fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
//!     where
//!         DB::ErrorType: 'static,
//!     {
//!         let mut chart = ChartBuilder::on(root).build_cartesian_2d(0.0..1.0, 0.0..1.0)?;
//!         chart.draw_series(LineSeries::new(self.0.iter().copied(), &BLUE))?;
//!         Ok(())
//!     }
//! }
//!
//! // line.png and line.svg
//! let files = write_png_and_svg(std::path::Path::new("out/line"), (800, 600), &Line(vec![(0.0, 0.0), (1.0, 1.0)]))?;
//! # Ok::<(), nerve_plot_font::figure::FigureError>(())
//! ```

use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// What drawing a figure can fail with: plotters' error (any backend's,
/// with `?`), or a message.
pub type DrawError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// The result of [`Figure::draw`].
pub type DrawResult = Result<(), DrawError>;

/// A figure: what it draws, on any of plotters' backends.
pub trait Figure {
    /// Draws the figure on `root`, which is white and whose text has the
    /// project's font; the caller writes the file afterwards.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static;
}

/// A figure that could not be written.
#[derive(Debug, thiserror::Error)]
pub enum FigureError {
    /// Drawing or writing the file failed.
    #[error("cannot write the figure {path}: {source} (is its folder there and writable?)")]
    Write {
        /// The file.
        path: PathBuf,
        /// plotters' error, or the figure's own.
        #[source]
        source: DrawError,
    },
}

/// The file formats of a figure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// A bitmap (`.png`).
    Png,
    /// A vector drawing (`.svg`).
    Svg,
}

impl Format {
    /// The file name extension.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Png => "png",
            Format::Svg => "svg",
        }
    }
}

/// Sets the figure up on `root`, draws it and writes it.
fn render<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, figure: &impl Figure) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    figure.draw(&root)?;
    root.present()?;
    Ok(())
}

/// Writes `figure` to `path` in `format`, `size` pixels (for SVG, its units).
pub fn write(path: &Path, format: Format, size: (u32, u32), figure: &impl Figure) -> Result<(), FigureError> {
    crate::register();
    let drawn = match format {
        Format::Png => render(BitMapBackend::new(path, size).into_drawing_area(), figure),
        Format::Svg => render(SVGBackend::new(path, size).into_drawing_area(), figure),
    };
    drawn.map_err(|source| FigureError::Write { path: path.to_path_buf(), source })
}

/// Writes `figure` as the PNG file `path`.
pub fn write_png(path: &Path, size: (u32, u32), figure: &impl Figure) -> Result<(), FigureError> {
    write(path, Format::Png, size, figure)
}

/// Writes `figure` as the SVG file `path`.
pub fn write_svg(path: &Path, size: (u32, u32), figure: &impl Figure) -> Result<(), FigureError> {
    write(path, Format::Svg, size, figure)
}

/// Writes the PNG file `path` drawn by `draw`, for a figure drawn only as a
/// bitmap (the benchmarks'): set up and written as [`write`] does.
pub fn write_png_with(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> DrawResult,
) -> Result<(), FigureError> {
    crate::register();
    let root = BitMapBackend::new(path, size).into_drawing_area();
    let drawn = (|| -> DrawResult {
        root.fill(&WHITE)?;
        draw(&root)?;
        root.present()?;
        Ok(())
    })();
    drawn.map_err(|source| FigureError::Write { path: path.to_path_buf(), source })
}

/// Writes `figure` as `STEM.png` and `STEM.svg` (`stem` is the path
/// without the extension, e.g. `out/trajectory`); returns both paths.
pub fn write_png_and_svg(stem: &Path, size: (u32, u32), figure: &impl Figure) -> Result<[PathBuf; 2], FigureError> {
    let files = [Format::Png, Format::Svg].map(|f| with_extension(stem, f));
    write(&files[0], Format::Png, size, figure)?;
    write(&files[1], Format::Svg, size, figure)?;
    Ok(files)
}

/// Draws the legend of `chart`'s labelled series at `position`, in the
/// figures' one style: a white, slightly transparent box with a grey
/// border, text of `font` pixels.
pub fn legend<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
    font: u32,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend + 'a,
    CT: plotters::coord::CoordTranslate,
{
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .position(position)
        .label_font((crate::FAMILY, font))
        .draw()
}

/// `stem` with the format's extension added (not replacing a dot in the name).
fn with_extension(stem: &Path, format: Format) -> PathBuf {
    let mut s = stem.as_os_str().to_owned();
    s.push(".");
    s.push(format.extension());
    PathBuf::from(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A diagonal line and a title.
    struct Diagonal;

    impl Figure for Diagonal {
        fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
        where
            DB::ErrorType: 'static,
        {
            let mut chart = ChartBuilder::on(root)
                .caption("diagonal", (crate::FAMILY, 20))
                .build_cartesian_2d(0.0..1.0, 0.0..1.0)?;
            chart.draw_series(LineSeries::new([(0.0, 0.0), (1.0, 1.0)], &BLUE))?.label("rising");
            legend(&mut chart, SeriesLabelPosition::UpperLeft, 12)?;
            Ok(())
        }
    }

    /// A figure that fails to draw.
    struct Broken;

    impl Figure for Broken {
        fn draw<DB: DrawingBackend>(&self, _root: &DrawingArea<DB, Shift>) -> DrawResult
        where
            DB::ErrorType: 'static,
        {
            Err("no data".into())
        }
    }

    fn tmp(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("nerve-figure-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("a temporary folder");
        d
    }

    #[test]
    fn both_files_are_written_with_their_text() {
        let d = tmp("both");
        let files = write_png_and_svg(&d.join("fig.v2"), (300, 200), &Diagonal).expect("written");
        assert_eq!(files, [d.join("fig.v2.png"), d.join("fig.v2.svg")]);
        let png = std::fs::read(&files[0]).expect("png");
        assert!(png.starts_with(b"\x89PNG"), "a PNG file");
        let svg = std::fs::read_to_string(&files[1]).expect("svg");
        assert!(svg.contains("<svg") && svg.contains("diagonal") && svg.contains("rising"), "{svg}");
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_failure_names_the_file_and_keeps_its_cause() {
        let d = tmp("fail");
        let e = write_png(&d.join("broken.png"), (100, 100), &Broken).expect_err("it fails");
        assert!(e.to_string().contains("broken.png") && e.to_string().contains("no data"), "{e}");
        assert!(std::error::Error::source(&e).is_some_and(|s| s.to_string() == "no data"));
        let e =
            write_png_with(&d.join("closure.png"), (100, 100), |_| Err("nothing to draw".into())).expect_err("fails");
        assert!(e.to_string().contains("closure.png") && e.to_string().contains("nothing to draw"), "{e}");
        write_png_with(&d.join("ok.png"), (100, 100), |root| Diagonal.draw(root)).expect("a closure's figure");
        assert!(std::fs::read(d.join("ok.png")).expect("png").starts_with(b"\x89PNG"));
        let missing = d.join("no-such-folder").join("f");
        let e = write_png_and_svg(&missing, (100, 100), &Diagonal).expect_err("no folder");
        assert!(e.to_string().contains("no-such-folder"), "{e}");
        std::fs::remove_dir_all(&d).ok();
    }
}
