//! Videos of rollouts (`dextrain eval --video`, `play --video`, `replay --video`): the episodes a
//! recording would hold ([`RolloutMeta`] + [`RolloutFrame`]s) rendered headless with wgpu on any
//! adapter (lavapipe included) and encoded as MP4 (H.264), GIF or PNG frames.
//!
//! A video frame is two views side by side, each `--video-size` (default 480×360): on the left the
//! fixed camera (the workspace from the front right, above the table), on the right the follow
//! camera (its target eases toward the object, [`camera::FollowTarget`]); under them a caption
//! strip of [`caption::CAPTION_HEIGHT`] pixels: `episode k/N   step s/L   t = … s   success: yes|no`
//! (the episode's outcome, known at its end, is shown on all its frames; `n/a` for `replay`). The
//! scene: the hand's collision shapes (grey), the object's pieces (orange), the table (top face at
//! z = 0), the reference ghost (translucent green) when the frame has one. Episodes follow each
//! other; every recorded frame is one video frame at 1/dt frames per second (real time).
//!
//! [`eval_strip`] makes the image strip of an evaluation: the first and the last frame of each
//! episode (a row each), at half size.

pub mod camera;
pub mod caption;
pub mod encode;
pub mod triangles;
pub mod render;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, anyhow, ensure};

use crate::gpu::context::GpuContext;
use crate::record::{RolloutFrame, RolloutMeta};
use camera::{Camera, FollowTarget};
use caption::{CAPTION_HEIGHT, Caption, caption_strip};
pub use encode::{VideoFormat, VideoWriter};
use render::SceneRenderer;

/// The size of each of the two views, pixels (`--video-size WxH`; even numbers, for H.264).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ViewSize {
    /// Width of one view, pixels.
    pub width: u32,
    /// Height of one view, pixels.
    pub height: u32,
}

impl Default for ViewSize {
    fn default() -> Self {
        ViewSize { width: 480, height: 360 }
    }
}

impl std::str::FromStr for ViewSize {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<ViewSize, String> {
        let bad = || format!("view size '{s}': expected WIDTHxHEIGHT with even numbers from 16 to 4096, e.g. 480x360");
        let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
        let (width, height): (u32, u32) = (w.trim().parse().map_err(|_| bad())?, h.trim().parse().map_err(|_| bad())?);
        let ok = |v: u32| (16..=4096).contains(&v) && v % 2 == 0;
        if ok(width) && ok(height) { Ok(ViewSize { width, height }) } else { Err(bad()) }
    }
}

impl std::fmt::Display for ViewSize {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.width, self.height)
    }
}

/// The video flags of `eval`, `play` and `replay`.
#[derive(clap::Args, Debug, Clone, PartialEq)]
pub struct VideoArgs {
    /// Render episodes to this video: a path ending in .mp4 (H.264), .gif, .png (numbered PNG
    /// frames beside it) or / (a folder of PNG frames). Needs a wgpu adapter (a GPU, or lavapipe).
    #[arg(long)]
    pub video: Option<PathBuf>,
    /// How many episodes the video shows (eval, play: those of the first envs, one after another).
    #[arg(long, default_value_t = 4)]
    pub video_episodes: usize,
    /// Size of each of the video's two views (fixed and follow camera), WIDTHxHEIGHT, even.
    #[arg(long, default_value_t = ViewSize::default())]
    pub video_size: ViewSize,
}

impl Default for VideoArgs {
    fn default() -> Self {
        VideoArgs { video: None, video_episodes: 4, video_size: ViewSize::default() }
    }
}

/// One episode to render: what a recording of it holds, and its outcome.
#[derive(Clone, Debug)]
pub struct VideoEpisode {
    /// The hand, the object's pieces (scaled) and dt, as a recording of the episode holds them.
    pub meta: RolloutMeta,
    /// Its frames, one per recorded step (the first: the reset state).
    pub frames: Vec<RolloutFrame>,
    /// The task's success at the episode's end (None: not known, e.g. `replay`).
    pub success: Option<bool>,
}

/// What [`write_video`] wrote.
#[derive(Clone, Debug)]
pub struct VideoSummary {
    /// Where the video is.
    pub path: PathBuf,
    /// Its format (from the path).
    pub format: VideoFormat,
    /// Frames written (the sum of the episodes' frames).
    pub frames: usize,
    /// Frame width, pixels (2 views).
    pub width: u32,
    /// Frame height, pixels (a view and the caption).
    pub height: u32,
    /// Frames per second (1 / the first episode's dt).
    pub fps: f64,
    /// The adapter that rendered.
    pub adapter: String,
    /// Time spent building the triangles, rendering (with readback) and drawing captions, s.
    pub render_s: f64,
    /// Time spent encoding and writing, s.
    pub encode_s: f64,
    /// The first and the last frame of each episode (RGBA8, `width` × `height`), for the strip.
    pub ends: Vec<(Vec<u8>, Vec<u8>)>,
}

/// A GPU context to render on: `existing` (the evaluation's) when there is one, else a hardware
/// adapter, else lavapipe; none at all is a one-line error.
pub fn video_context(existing: Option<&GpuContext>) -> Result<GpuContext> {
    if let Some(ctx) = existing {
        return Ok(ctx.clone());
    }
    GpuContext::new(None).or_else(|hw| {
        GpuContext::new(Some("llvmpipe")).map_err(|sw| {
            anyhow!("--video needs a wgpu adapter to render on (a GPU, or lavapipe: apt install mesa-vulkan-drivers), and found none: {}; {}", crate::text::one_line(&format!("{hw:#}")), crate::text::one_line(&format!("{sw:#}")))
        })
    })
}

/// Renders frames of rollouts: the scene through both cameras, and the caption.
pub struct FrameRenderer {
    scene: SceneRenderer,
    view: ViewSize,
}

impl FrameRenderer {
    /// A renderer of `view`-sized views on `ctx`.
    pub fn new(ctx: GpuContext, view: ViewSize) -> Result<FrameRenderer> {
        ensure!(view.width % 2 == 0 && view.height % 2 == 0, "video view size {view}: expected even numbers");
        Ok(FrameRenderer { scene: SceneRenderer::new(ctx, view.width, view.height)?, view })
    }

    /// The size of a frame: (2 · view width, view height + the caption's height).
    pub fn frame_size(&self) -> (u32, u32) {
        (2 * self.view.width, self.view.height + CAPTION_HEIGHT)
    }

    /// The adapter it renders on.
    pub fn adapter(&self) -> String {
        self.scene.adapter()
    }

    /// The two cameras of a frame: the fixed one (left) and `follow` (right).
    pub fn cameras(follow: Camera) -> [Camera; 2] {
        [Camera::fixed(), follow]
    }

    /// One frame (RGBA8, [`frame_size`](Self::frame_size)): `frame` of `meta` through the fixed
    /// camera and `follow`, and the caption's `text` under them.
    pub fn render(&mut self, meta: &RolloutMeta, frame: &RolloutFrame, follow: Camera, text: &str) -> Result<Vec<u8>> {
        let (opaque, ghost) = triangles::frame_triangles(meta, frame);
        let aspect = self.view.width as f32 / self.view.height as f32;
        let [a, b] = Self::cameras(follow);
        let mut image = self.scene.render(&opaque, &ghost, [a.view_proj(aspect), b.view_proj(aspect)])?;
        image.extend_from_slice(&caption_strip(text, 2 * self.view.width)?);
        Ok(image)
    }
}

impl VideoArgs {
    /// The number of episodes to film when `--video` is given (0 without it), checked before
    /// anything runs: a path of no known format, an MP4 in a build without the `video` feature, or
    /// `--video-episodes 0` is a one-line error.
    pub fn episodes_to_film(&self) -> Result<usize> {
        let Some(path) = &self.video else { return Ok(0) };
        check_output(path)?;
        ensure!(self.video_episodes > 0, "--video {}: --video-episodes 0 films nothing; expected at least 1", path.display());
        Ok(self.video_episodes)
    }

    /// With `--video`, the context to render on ([`video_context`] without an existing one),
    /// opened before anything runs, so that a machine without any adapter fails at once.
    pub fn render_context(&self) -> Result<Option<GpuContext>> {
        self.video.as_ref().map(|_| video_context(None)).transpose()
    }
}

/// The format of the video at `path`, checked before anything is run: a path of no known format,
/// or an MP4 in a build without the `video` feature, is a one-line error naming it.
pub fn check_output(path: &Path) -> Result<VideoFormat> {
    let format = VideoFormat::from_path(path)?;
    ensure!(format.available(), "video {}: this build has no MP4 encoder (built without the `video` feature): write a .gif or PNG frames, or rebuild with `--features video` (needs a C++ compiler)", path.display());
    Ok(format)
}

/// Renders `episodes` one after another into the video at `path` (format from the path) on
/// `ctx`, `view`-sized views, at 1 / dt frames per second (the first episode's dt, to a
/// thousandth).
pub fn write_video(path: &Path, episodes: &[VideoEpisode], ctx: GpuContext, view: ViewSize) -> Result<VideoSummary> {
    let format = check_output(path)?;
    ensure!(!episodes.is_empty(), "video {}: no episodes to render", path.display());
    let dt = episodes[0].meta.dt;
    ensure!(dt.is_finite() && dt > 0.0, "video {}: the episodes' dt is {dt}: expected a finite time > 0", path.display());
    // 1 / dt to a thousandth (dt is an f32: 1/30 s gives 29.999998 unrounded)
    let fps = (1e3 / dt as f64).round() / 1e3;
    let mut renderer = FrameRenderer::new(ctx, view).with_context(|| format!("video {}", path.display()))?;
    let (width, height) = renderer.frame_size();
    let mut writer = VideoWriter::create(path, width, height, fps)?;
    let (mut render_s, mut encode_s) = (0.0, 0.0);
    let mut ends = Vec::with_capacity(episodes.len());
    for (e, episode) in episodes.iter().enumerate() {
        let mut follow = FollowTarget::new();
        let last = episode.frames.len().saturating_sub(1);
        let mut first_image = None;
        for (s, frame) in episode.frames.iter().enumerate() {
            let caption = Caption { episode: e + 1, episodes: episodes.len(), step: s, last_step: last, t: frame.t, success: episode.success };
            let started = Instant::now();
            let image = renderer.render(&episode.meta, frame, follow.update(frame.object.pos), &caption.text()).with_context(|| format!("video {}: episode {} frame {s}", path.display(), e + 1))?;
            let rendered = Instant::now();
            writer.push(&image)?;
            render_s += (rendered - started).as_secs_f64();
            encode_s += rendered.elapsed().as_secs_f64();
            if s == 0 {
                first_image = Some(image.clone());
            }
            if s == last {
                ends.push((first_image.take().unwrap_or_else(|| image.clone()), image));
            }
        }
    }
    let started = Instant::now();
    let frames = writer.finish()?;
    encode_s += started.elapsed().as_secs_f64();
    Ok(VideoSummary { path: path.to_path_buf(), format, frames, width, height, fps, adapter: renderer.adapter(), render_s, encode_s, ends })
}

/// Halves an RGBA8 image (`width`, `height` even): each output pixel the mean of a 2×2 block.
fn half_size(rgba: &[u8], width: u32, height: u32) -> Vec<u8> {
    let (w, h) = (width as usize / 2, height as usize / 2);
    let mut out = vec![0u8; w * h * 4];
    for y in 0..h {
        for x in 0..w {
            for c in 0..4 {
                let at = |dx: usize, dy: usize| rgba[4 * ((2 * y + dy) * width as usize + 2 * x + dx) + c] as u32;
                // (a + b + c + d + 2) / 4: the rounded mean
                out[4 * (y * w + x) + c] = ((at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1) + 2) / 4) as u8;
            }
        }
    }
    out
}

/// The size of the strip of `episodes` episodes whose frames are `width` × `height`: two
/// half-size frames per row, a row per episode.
pub fn strip_size(episodes: usize, width: u32, height: u32) -> (u32, u32) {
    (2 * (width / 2), episodes as u32 * (height / 2))
}

/// Writes the image strip of a video (PNG at `path`): per episode a row holding its first and its
/// last frame at half size ([`strip_size`]).
pub fn eval_strip(path: &Path, video: &VideoSummary) -> Result<()> {
    ensure!(!video.ends.is_empty(), "image strip {}: no episodes", path.display());
    let (tw, th) = ((video.width / 2) as usize, (video.height / 2) as usize);
    let (sw, sh) = strip_size(video.ends.len(), video.width, video.height);
    let mut strip = vec![0u8; sw as usize * sh as usize * 4];
    for (row, (first, last)) in video.ends.iter().enumerate() {
        for (col, image) in [first, last].into_iter().enumerate() {
            let tile = half_size(image, video.width, video.height);
            for y in 0..th {
                // tile row y → strip row (row·th + y), from column col·tw
                let dst = 4 * ((row * th + y) * sw as usize + col * tw);
                strip[dst..dst + 4 * tw].copy_from_slice(&tile[4 * y * tw..4 * (y + 1) * tw]);
            }
        }
    }
    encode::write_png_file(path, &strip, sw, sh)
}
