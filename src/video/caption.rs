//! The caption strip under a video frame: one line of text (episode, step, time, success) drawn
//! on the CPU with DejaVu Sans (the font the plots embed) through `ab_glyph`.

use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};
use anyhow::{Result, anyhow};

/// Height of the caption strip (pixels; even, for H.264).
pub const CAPTION_HEIGHT: u32 = 28;
/// Height of the text (pixels).
const TEXT_PX: f32 = 18.0;
/// Left margin of the text (pixels).
const MARGIN: f32 = 8.0;
/// Strip background and text colours, RGB.
const STRIP_RGB: [u8; 3] = [32, 32, 36];
const TEXT_RGB: [u8; 3] = [240, 240, 240];

/// What a caption says about a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Caption {
    /// Which episode of the video (from 1).
    pub episode: usize,
    /// How many episodes the video has.
    pub episodes: usize,
    /// The frame's step within its episode (0 = the reset state).
    pub step: usize,
    /// The episode's last step (its frames − 1).
    pub last_step: usize,
    /// Simulated time (s).
    pub t: f64,
    /// The episode's outcome (known at its end, shown on all of its frames); None where there is
    /// none (`replay`).
    pub success: Option<bool>,
}

impl Caption {
    /// `episode 1/4   step 12/60   t = 0.40 s   success: yes`.
    pub fn text(&self) -> String {
        let outcome = match self.success {
            Some(true) => "success: yes",
            Some(false) => "success: no",
            None => "success: n/a",
        };
        format!("episode {}/{}   step {}/{}   t = {:.2} s   {outcome}", self.episode, self.episodes, self.step, self.last_step, self.t)
    }
}

/// Draws `text` into a new strip of `width` × [`CAPTION_HEIGHT`] RGBA8 pixels (text clipped at the
/// right edge).
pub fn caption_strip(text: &str, width: u32) -> Result<Vec<u8>> {
    let font = FontRef::try_from_slice(crate::plot::FONT).map_err(|_| anyhow!("the embedded font assets/DejaVuSans.ttf could not be parsed"))?;
    let scaled = font.as_scaled(PxScale::from(TEXT_PX));
    let (w, h) = (width as usize, CAPTION_HEIGHT as usize);
    let mut strip: Vec<u8> = std::iter::repeat_n([STRIP_RGB[0], STRIP_RGB[1], STRIP_RGB[2], 255], w * h).flatten().collect();
    // the baseline: the text's box (ascent − descent) centred in the strip
    let baseline = 0.5 * (CAPTION_HEIGHT as f32 + scaled.ascent() + scaled.descent());
    let mut x = MARGIN;
    let mut previous = None;
    for c in text.chars() {
        let id = font.glyph_id(c);
        if let Some(p) = previous {
            x += scaled.kern(p, id);
        }
        previous = Some(id);
        let glyph = id.with_scale_and_position(TEXT_PX, point(x, baseline));
        x += scaled.h_advance(id);
        let Some(outline) = font.outline_glyph(glyph) else { continue };
        let bounds = outline.px_bounds();
        outline.draw(|gx, gy, coverage| {
            let (px, py) = (bounds.min.x as i64 + gx as i64, bounds.min.y as i64 + gy as i64);
            if px < 0 || py < 0 || px >= w as i64 || py >= h as i64 {
                return;
            }
            let k = 4 * (py as usize * w + px as usize);
            // out = bg + coverage · (text − bg)
            for ch in 0..3 {
                let (bg, fg) = (STRIP_RGB[ch] as f32, TEXT_RGB[ch] as f32);
                strip[k + ch] = (bg + coverage.clamp(0.0, 1.0) * (fg - bg)).round() as u8;
            }
        });
    }
    Ok(strip)
}
