//! Writing rendered frames: MP4 (H.264: OpenH264 encodes, muxide muxes; the `video` feature), an
//! animated GIF, or numbered PNG files, chosen from the output path. MP4 and GIF are written to a
//! hidden temporary file beside the target and renamed to it by [`VideoWriter::finish`]: an
//! interrupted run never leaves a half-written video under the final name (dropping an unfinished
//! writer removes the temporary file). PNG frames are each written the same way.

use std::fs::{self, File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail, ensure};

/// The output format of a video, chosen from its path ([`VideoFormat::from_path`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VideoFormat {
    /// `.mp4`: H.264 in an MP4 container.
    Mp4,
    /// `.gif`: an animated GIF (256 colours per frame), looping.
    Gif,
    /// A folder (a path ending in `/`, or an existing folder): `frame_00000.png`, … in it; or a
    /// path ending in `.png`: `STEM_00000.png`, … beside it.
    PngFrames,
}

impl VideoFormat {
    /// The format a path asks for; anything else is a one-line error naming the path.
    pub fn from_path(path: &Path) -> Result<VideoFormat> {
        let text = path.to_string_lossy();
        if text.ends_with('/') || path.is_dir() {
            return Ok(VideoFormat::PngFrames);
        }
        match path.extension().map(|e| e.to_string_lossy().to_lowercase()).as_deref() {
            Some("mp4") => Ok(VideoFormat::Mp4),
            Some("gif") => Ok(VideoFormat::Gif),
            Some("png") => Ok(VideoFormat::PngFrames),
            _ => bail!("video {}: expected a path ending in .mp4 (H.264), .gif, .png (numbered frames) or / (a folder of PNG frames)", path.display()),
        }
    }

    /// Whether this build can write the format (MP4 needs the `video` feature).
    pub fn available(self) -> bool {
        self != VideoFormat::Mp4 || cfg!(feature = "video")
    }
}

/// Creates `tmp` (new) for writing, naming `dest` in the error.
fn create_temp(tmp: &Path, dest: &Path) -> Result<BufWriter<File>> {
    crate::files::create_parent_dir(dest).with_context(|| format!("creating video {}", dest.display()))?;
    let file = OpenOptions::new().write(true).create_new(true).open(tmp).with_context(|| format!("creating video {} (temporary file {})", dest.display(), tmp.display()))?;
    Ok(BufWriter::new(file))
}

/// Flushes and syncs `w`, then renames `tmp` to `dest`.
fn commit(w: BufWriter<File>, tmp: &Path, dest: &Path) -> Result<()> {
    let file = w.into_inner().map_err(|e| e.into_error()).with_context(|| format!("writing video {}", dest.display()))?;
    file.sync_all().with_context(|| format!("writing video {}", dest.display()))?;
    drop(file);
    fs::rename(tmp, dest).with_context(|| format!("renaming {} to {}", tmp.display(), dest.display()))
}

/// Writes one RGBA8 image (`width` × `height`, rows top first) as a PNG stream.
pub fn write_png<W: Write>(w: W, rgba: &[u8], width: u32, height: u32) -> Result<()> {
    let mut enc = png::Encoder::new(w, width, height);
    enc.set_color(png::ColorType::Rgba);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header()?;
    writer.write_image_data(rgba)?;
    writer.finish()?;
    Ok(())
}

/// Writes one RGBA8 image as the PNG file `path` (through a temporary file).
pub fn write_png_file(path: &Path, rgba: &[u8], width: u32, height: u32) -> Result<()> {
    let tmp = crate::files::temp_path_beside(path)?;
    let mut w = create_temp(&tmp, path)?;
    let written = write_png(&mut w, rgba, width, height).with_context(|| format!("writing image {}", path.display())).and_then(|()| commit(w, &tmp, path));
    if written.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    written
}

/// The MP4 encoder: OpenH264 (frames never skipped, so every frame is one sample) into muxide
/// (Annex-B access units, one per frame at pts = i / fps).
#[cfg(feature = "video")]
struct Mp4Sink {
    encoder: openh264::encoder::Encoder,
    muxer: muxide::api::Muxer<BufWriter<File>>,
    yuv: openh264::formats::YUVBuffer,
    annexb: Vec<u8>,
}

#[cfg(feature = "video")]
impl Mp4Sink {
    fn new(w: BufWriter<File>, width: u32, height: u32, fps: f64) -> Result<Mp4Sink> {
        use openh264::encoder::{BitRate, EncoderConfig, FrameRate, IntraFramePeriod, RateControlMode};
        // ~0.15 bit per pixel per frame: sharp edges on flat colours at a few Mbit/s
        let bps = (0.15 * width as f64 * height as f64 * fps).clamp(500_000.0, 20_000_000.0) as u32;
        let config = EncoderConfig::new()
            .skip_frames(false)
            .bitrate(BitRate::from_bps(bps))
            .max_frame_rate(FrameRate::from_hz(fps as f32))
            // the buffer-based mode: quality adapts to the buffer, no frame is ever skipped (the
            // bitrate modes warn on stderr that they cannot hold a bitrate without skipping)
            .rate_control_mode(RateControlMode::Bufferbased)
            // a key frame every 2 s, so a player can seek
            .intra_frame_period(IntraFramePeriod::from_num_frames((2.0 * fps).round().max(1.0) as u32))
            .num_threads(1);
        let encoder = openh264::encoder::Encoder::with_api_config(openh264::OpenH264API::from_source(), config)?;
        let muxer = muxide::api::MuxerBuilder::new(w).video(muxide::api::VideoCodec::H264, width, height, fps).build()?;
        Ok(Mp4Sink { encoder, muxer, yuv: openh264::formats::YUVBuffer::new(width as usize, height as usize), annexb: Vec::new() })
    }

    fn push(&mut self, rgba: &[u8], width: u32, height: u32, pts: f64) -> Result<()> {
        use openh264::encoder::FrameType;
        self.yuv.read_rgba8(openh264::formats::RgbaSliceU8::new(rgba, (width as usize, height as usize)));
        let bits = self.encoder.encode(&self.yuv)?;
        let key = matches!(bits.frame_type(), FrameType::IDR | FrameType::I);
        self.annexb.clear();
        bits.write_vec(&mut self.annexb);
        ensure!(!self.annexb.is_empty(), "the H.264 encoder produced no data for a frame");
        self.muxer.write_video(pts, &self.annexb, key)?;
        Ok(())
    }

    fn finish(mut self) -> Result<BufWriter<File>> {
        self.muxer.finish_in_place()?;
        Ok(self.muxer.into_writer())
    }
}

/// Where the frames go.
enum Sink {
    #[cfg(feature = "video")]
    Mp4(Box<Mp4Sink>),
    Gif(Box<gif::Encoder<BufWriter<File>>>),
    /// PNG files `prefix_00000.png`, … (`prefix` a path without the number and extension).
    Png { prefix: PathBuf },
}

/// Writes a video frame by frame: [`VideoWriter::create`], [`push`](VideoWriter::push) each
/// RGBA8 frame, [`finish`](VideoWriter::finish).
pub struct VideoWriter {
    format: VideoFormat,
    dest: PathBuf,
    /// The temporary file (MP4, GIF) until `finish` renames it.
    tmp: Option<PathBuf>,
    sink: Option<Sink>,
    width: u32,
    height: u32,
    fps: f64,
    frames: usize,
}

impl VideoWriter {
    /// A video of `width` × `height` frames at `fps` frames per second at `path` (format from the
    /// path). Errors are one line naming the path.
    pub fn create(path: &Path, width: u32, height: u32, fps: f64) -> Result<VideoWriter> {
        let format = VideoFormat::from_path(path)?;
        ensure!(fps.is_finite() && fps > 0.0, "video {}: frame rate {fps}: expected a finite rate > 0", path.display());
        ensure!(width > 0 && height > 0, "video {}: frame size {width}x{height}: expected both > 0", path.display());
        let (sink, tmp) = match format {
            VideoFormat::Mp4 => {
                ensure!(width % 2 == 0 && height % 2 == 0, "video {}: H.264 needs an even frame size (got {width}x{height})", path.display());
                #[cfg(feature = "video")]
                {
                    let tmp = crate::files::temp_path_beside(path)?;
                    let w = create_temp(&tmp, path)?;
                    match Mp4Sink::new(w, width, height, fps) {
                        Ok(s) => (Sink::Mp4(Box::new(s)), Some(tmp)),
                        Err(e) => {
                            let _ = fs::remove_file(&tmp);
                            return Err(e.context(format!("creating video {}", path.display())));
                        }
                    }
                }
                #[cfg(not(feature = "video"))]
                bail!("video {}: this build has no MP4 encoder (built without the `video` feature): write a .gif or PNG frames, or rebuild with `--features video` (needs a C++ compiler)", path.display())
            }
            VideoFormat::Gif => {
                ensure!(width <= u16::MAX as u32 && height <= u16::MAX as u32, "video {}: a GIF is at most 65535 pixels on a side (got {width}x{height})", path.display());
                let tmp = crate::files::temp_path_beside(path)?;
                let w = create_temp(&tmp, path)?;
                let made = gif::Encoder::new(w, width as u16, height as u16, &[]).and_then(|mut e| e.set_repeat(gif::Repeat::Infinite).map(|()| e));
                match made {
                    Ok(e) => (Sink::Gif(Box::new(e)), Some(tmp)),
                    Err(e) => {
                        let _ = fs::remove_file(&tmp);
                        bail!("creating video {}: {e}", path.display());
                    }
                }
            }
            VideoFormat::PngFrames => {
                let text = path.to_string_lossy();
                let prefix = if text.ends_with('/') || path.is_dir() {
                    path.join("frame")
                } else {
                    path.with_extension("")
                };
                let dir = prefix.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
                fs::create_dir_all(dir).with_context(|| format!("creating video folder {}", dir.display()))?;
                (Sink::Png { prefix }, None)
            }
        };
        Ok(VideoWriter { format, dest: path.to_path_buf(), tmp, sink: Some(sink), width, height, fps, frames: 0 })
    }

    /// The format being written.
    pub fn format(&self) -> VideoFormat {
        self.format
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Appends one frame: RGBA8, `width` × `height`, rows top first.
    pub fn push(&mut self, rgba: &[u8]) -> Result<()> {
        let (w, h) = (self.width, self.height);
        ensure!(rgba.len() == (w * h * 4) as usize, "video {}: a frame of {} bytes, expected {w}x{h}x4 = {}", self.dest.display(), rgba.len(), w * h * 4);
        let dest = self.dest.clone();
        match self.sink.as_mut().expect("the sink is only taken by finish") {
            #[cfg(feature = "video")]
            Sink::Mp4(s) => s.push(rgba, w, h, self.frames as f64 / self.fps).with_context(|| format!("writing video {} frame {}", dest.display(), self.frames))?,
            Sink::Gif(e) => {
                let mut pixels = rgba.to_vec();
                // speed 10 of 1..30: NeuQuant's sampling (quality vs time)
                let mut frame = gif::Frame::from_rgba_speed(w as u16, h as u16, &mut pixels, 10);
                // delay in 1/100 s
                frame.delay = (100.0 / self.fps).round().max(1.0) as u16;
                e.write_frame(&frame).with_context(|| format!("writing video {} frame {}", dest.display(), self.frames))?;
            }
            Sink::Png { prefix } => {
                let file = PathBuf::from(format!("{}_{:05}.png", prefix.display(), self.frames));
                write_png_file(&file, rgba, w, h)?;
            }
        }
        self.frames += 1;
        Ok(())
    }

    /// Completes the video and moves it to its path; returns the frames written.
    pub fn finish(mut self) -> Result<usize> {
        let dest = self.dest.clone();
        let sink = self.sink.take().expect("the sink is only taken by finish");
        let tmp = self.tmp.clone();
        let result = (|| -> Result<()> {
            match sink {
                #[cfg(feature = "video")]
                Sink::Mp4(s) => {
                    ensure!(self.frames >= 2, "an MP4 needs at least 2 frames (got {})", self.frames);
                    commit(s.finish()?, tmp.as_deref().expect("an MP4 has a temporary file"), &dest)
                }
                Sink::Gif(e) => commit(e.into_inner()?, tmp.as_deref().expect("a GIF has a temporary file"), &dest),
                Sink::Png { .. } => Ok(()),
            }
        })()
        .with_context(|| format!("finishing video {}", dest.display()));
        if result.is_ok() {
            self.tmp = None;
        }
        // on error, Drop removes the temporary file
        result.map(|()| self.frames)
    }
}

impl Drop for VideoWriter {
    fn drop(&mut self) {
        // an unfinished MP4 or GIF: close it, then remove its temporary file
        drop(self.sink.take());
        if let Some(tmp) = self.tmp.take() {
            let _ = fs::remove_file(&tmp);
        }
    }
}
