//! The font of nerve's figures: DejaVu Sans, compiled into the binary and
//! registered with plotters' `ab_glyph` text backend as `sans-serif` (the
//! family every figure asks for).
//!
//! plotters' default `ttf` backend finds the system's fonts through
//! fontconfig and draws them with freetype. Linking those (and expat, png,
//! brotli and z behind them) cost every `nerve` command, plotting or not,
//! about a fifth of its start-up in the dynamic loader (a profile of
//! `nerve --version`), and made the CLI need them installed on the robot.
//! DejaVu Sans is what fontconfig chose for `sans-serif` on the machines
//! nerve is developed on, so the figures look as they did.
//!
//! Call [`register`] before drawing text; it is cheap after the first call.
//! [`figure`] does it, and the rest of a figure's set-up: every figure of
//! nerve is written through it.

pub mod figure;

use plotters::style::{FontStyle, register_font};
use std::sync::Once;

/// The family the font is registered as: what `("sans-serif", size)` and
/// `FontFamily::SansSerif` look up.
pub const FAMILY: &str = "sans-serif";

/// Registers DejaVu Sans (regular and bold) as [`FAMILY`], once per
/// process. Figures drawn before it have no text: plotters' `ab_glyph`
/// backend knows no other font.
pub fn register() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let faces =
            [(FontStyle::Normal, "regular", dejavu::sans::regular()), (FontStyle::Bold, "bold", dejavu::sans::bold())];
        for (style, face, bytes) in faces {
            // the bytes are a font shipped with the crate: only a broken
            // build of it could fail here, and then a figure has no text
            if register_font(FAMILY, style, bytes).is_err() {
                eprintln!("warning: the figures' font DejaVu Sans ({face}) could not be read; its text is left out");
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use plotters::prelude::*;

    /// A white `w` x `h` RGB image with `text` drawn at `pos` in `style`.
    fn drawn(w: u32, h: u32, text: &str, style: &TextStyle, pos: (i32, i32)) -> Vec<u8> {
        let mut buf = vec![255u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            root.draw_text(text, style, pos).expect("text drawn");
            root.present().expect("present");
        }
        buf
    }

    /// The positions (pixel indices) of an image's dark pixels.
    fn dark(buf: &[u8]) -> impl Iterator<Item = u32> + '_ {
        buf.chunks(3).enumerate().filter(|(_, p)| p.iter().all(|&c| c < 128)).map(|(i, _)| i as u32)
    }

    /// Text drawn after `register` lands on the image (a figure without
    /// its labels is what a missing font looks like).
    #[test]
    fn registered_text_is_drawn() {
        register();
        let buf = drawn(200, 60, "nerve 42", &(FAMILY, 30).into_font().color(&BLACK), (5, 10));
        let n = dark(&buf).count();
        assert!(n > 100, "only {n} dark pixels: the text was not drawn");
    }

    /// A y axis's description is drawn turned a quarter (taller than wide),
    /// as charts ask for it.
    #[test]
    fn turned_text_is_drawn_turned() {
        register();
        let w = 200;
        let style = TextStyle::from((FAMILY, 20).into_font()).transform(FontTransform::Rotate270).color(&BLACK);
        let buf = drawn(w, 200, "round trip", &style, (100, 150));
        let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0, 0);
        for i in dark(&buf) {
            let (x, y) = (i % w, i / w);
            (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
        }
        let (iw, ih) = (x1.saturating_sub(x0), y1.saturating_sub(y0));
        assert!(ih > 2 * iw && ih > 50, "ink {iw}x{ih}: not turned");
    }
}
