//! Videos (src/video/): a synthetic rollout rendered on lavapipe (or any adapter) and written as
//! MP4, GIF and PNG frames, read back by decoders independent of our encoder code (PyAV for the
//! MP4, tests/read_video.py; the `gif` and `png` crates' decoders), with the object's pixels where
//! the renderer's camera projects the object's position; and `dextrain eval`, `play` and `replay
//! --video` end to end.

use std::path::Path;
use std::process::Command;

use glam::{Quat, Vec3};

use dextrain::geom::{ObjectShape, Pose};
use dextrain::hand::{Collider, ColliderShape, HandModel};
use dextrain::record::{ObjectPart, RolloutFrame, RolloutMeta};
use dextrain::video::camera::{Camera, FollowTarget};
use dextrain::video::caption::CAPTION_HEIGHT;
use dextrain::video::{VideoEpisode, VideoFormat, VideoWriter, ViewSize, strip_size, write_video};

use super::common::gpu_context;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
/// 30 frames at 30 fps: a 1 s video.
const N_FRAMES: usize = 30;
const DT: f32 = 1.0 / 30.0;
const VIEW: ViewSize = ViewSize { width: 240, height: 180 };
/// The object: a 6 cm cube resting on the table.
const HALF: f32 = 0.03;

/// The tests' tiny hand (a palm and a finger) with a sphere on the finger, and no fingertip.
fn small_hand() -> HandModel {
    let mut hand = super::common::tiny_hand();
    hand.colliders.push(Collider { link: 1, pose: Pose::new(Vec3::new(0.0, 0.0, 0.05), Quat::IDENTITY), shape: ColliderShape::Sphere { radius: 0.012 } });
    hand.fingertips.clear();
    hand
}

/// The object's centre at frame k: from (0, 0, HALF) to (0.12, 0.08, HALF) over the video.
fn object_at(k: usize) -> Vec3 {
    let s = k as f32 / (N_FRAMES - 1) as f32;
    Vec3::new(0.12 * s, 0.08 * s, HALF)
}

/// One episode: the hand parked up and to the side (out of the object's way in the fixed view),
/// the cube sliding along the table; a reference ghost on odd frames.
fn episode() -> VideoEpisode {
    let hand = small_hand();
    let meta = RolloutMeta {
        hand: hand.clone(),
        object: vec![ObjectPart { shape: ObjectShape::Box { half_extents: [HALF; 3] }, pose: Pose::IDENTITY, triangles: Vec::new() }],
        dt: DT,
        info: serde_json::json!({ "command": "dextrain test" }),
    };
    let frames = (0..N_FRAMES)
        .map(|k| {
            let q = 0.04 * k as f32;
            let wrist = Pose::new(Vec3::new(-0.2, 0.2, 0.3), Quat::from_rotation_x(0.3));
            RolloutFrame {
                t: k as f64 * DT as f64,
                joint_pos: vec![q],
                joint_vel: vec![0.0],
                joint_target: vec![q],
                wrist,
                object: Pose::new(object_at(k), Quat::IDENTITY),
                links: hand.forward_kinematics(&[q]).iter().map(|p| wrist.mul(p)).collect(),
                contacts: Vec::new(),
                object_ref: (k % 2 == 1).then(|| Pose::new(Vec3::new(-0.1, -0.1, HALF), Quat::IDENTITY)),
                overlay: Vec::new(),
            }
        })
        .collect();
    VideoEpisode { meta, frames, success: Some(true) }
}

/// Orange, the object's colour under any of the lights' shades (not the grey hand or table, not
/// the pale blue sky, not the green ghost).
fn is_object_color([r, g, b]: [i64; 3]) -> bool {
    r >= 100 && r - b >= 70 && r > g
}

/// The pixel (column, row) of world point `p` in the left (fixed camera) view of a frame.
fn fixed_pixel(p: Vec3) -> (u32, u32) {
    let (x, y) = Camera::fixed().project(p, VIEW.width, VIEW.height).expect("the point is in the fixed camera's view");
    (x as u32, y as u32)
}

/// Whether PyAV can be imported; without it the test says why it did not run (or fails, with
/// REQUIRE_PYTHON_AV=1).
fn python_av(test: &str) -> bool {
    let required = std::env::var("REQUIRE_PYTHON_AV").is_ok_and(|v| v == "1");
    let probe = Command::new("python3").args(["-c", "import av"]).output();
    if probe.as_ref().is_ok_and(|o| o.status.success()) {
        return true;
    }
    assert!(!required, "{test}: REQUIRE_PYTHON_AV=1 but PyAV is not importable (pip install av==18.1.0)");
    eprintln!("{test}: PyAV read-back SKIPPED: PyAV is not importable (pip install av==18.1.0)");
    false
}

/// Reads `video` with tests/read_video.py: the stream's facts and the RGB of each probe
/// (frame, x, y).
fn read_with_pyav(video: &Path, probes: &[(usize, u32, u32)]) -> serde_json::Value {
    let probes = serde_json::to_string(&probes.iter().map(|&(f, x, y)| [f as u64, x as u64, y as u64]).collect::<Vec<_>>()).unwrap();
    let out = Command::new("python3").arg(Path::new(ROOT).join("tests/read_video.py")).arg(video).arg(probes).output().unwrap();
    assert!(out.status.success(), "read_video.py failed: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

fn rgb(v: &serde_json::Value) -> [i64; 3] {
    let a = v.as_array().expect("a probe's RGB");
    [0, 1, 2].map(|i| a[i].as_i64().unwrap())
}

fn rgb_at(rgba: &[u8], width: u32, (x, y): (u32, u32)) -> [i64; 3] {
    let k = 4 * (y as usize * width as usize + x as usize);
    [rgba[k] as i64, rgba[k + 1] as i64, rgba[k + 2] as i64]
}

#[test]
fn mp4_reads_back_with_its_size_frames_duration_and_the_object_where_the_camera_projects_it() {
    let Some(ctx) = gpu_context("video mp4") else { return };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.mp4");
    let v = write_video(&path, &[episode()], ctx, VIEW).expect("video");
    let (w, h) = (2 * VIEW.width, VIEW.height + CAPTION_HEIGHT);
    assert_eq!((v.format, v.frames, v.width, v.height, v.fps), (VideoFormat::Mp4, N_FRAMES, w, h, 30.0));
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "only the video, no temporary file left");
    assert_eq!(v.ends.len(), 1);
    // the renderer's own first frame: the object where the fixed camera projects it, and in the
    // follow view's centre (the follow camera starts on the object)
    let (first, last) = &v.ends[0];
    let at0 = fixed_pixel(object_at(0));
    assert!(is_object_color(rgb_at(first, w, at0)), "{:?} at {at0:?}", rgb_at(first, w, at0));
    let centre = (VIEW.width + VIEW.width / 2, VIEW.height / 2);
    assert!(is_object_color(rgb_at(first, w, centre)), "follow view centre {:?}", rgb_at(first, w, centre));
    let at_end = fixed_pixel(object_at(N_FRAMES - 1));
    assert!(is_object_color(rgb_at(last, w, at_end)) && !is_object_color(rgb_at(last, w, at0)), "the object moved");

    if !python_av("video mp4") {
        return;
    }
    // an independent decoder (FFmpeg through PyAV): codec, size, frame count, duration; the object's
    // pixel at its projection in the first and last frames, and not where it is not
    let far = fixed_pixel(Vec3::new(-0.3, -0.1, 0.0));
    let n = N_FRAMES - 1;
    let probes = [(0, at0.0, at0.1), (0, at_end.0, at_end.1), (n, at_end.0, at_end.1), (n, at0.0, at0.1), (0, far.0, far.1), (0, 4, VIEW.height + 4), (0, centre.0, centre.1)];
    let r = read_with_pyav(&path, &probes);
    assert_eq!(r["codec"], "h264", "{r}");
    assert_eq!((r["width"].as_u64(), r["height"].as_u64()), (Some(w as u64), Some(h as u64)), "{r}");
    assert_eq!(r["frames"].as_u64(), Some(N_FRAMES as u64), "{r}");
    let duration = r["duration"].as_f64().expect("a duration");
    assert!((duration - N_FRAMES as f64 / 30.0).abs() < 1e-3, "duration {duration} s, expected {} frames / 30 fps", N_FRAMES);
    assert!((r["fps"].as_f64().unwrap() - 30.0).abs() < 1e-6, "{r}");
    let p: Vec<[i64; 3]> = r["probes"].as_array().unwrap().iter().map(rgb).collect();
    assert!(is_object_color(p[0]), "frame 0: the object at its projection {at0:?}: {:?}", p[0]);
    assert!(!is_object_color(p[1]), "frame 0: not yet where it ends: {:?}", p[1]);
    assert!(is_object_color(p[2]), "frame {n}: the object at its new projection {at_end:?}: {:?}", p[2]);
    assert!(!is_object_color(p[3]), "frame {n}: gone from where it started: {:?}", p[3]);
    assert!(!is_object_color(p[4]), "frame 0: table far from the object: {:?}", p[4]);
    assert!(p[5].iter().all(|&c| c < 80), "the caption strip is dark: {:?}", p[5]);
    assert!(is_object_color(p[6]), "frame 0: the follow view's centre: {:?}", p[6]);
}

#[test]
fn gif_and_png_frames_read_back_with_the_gif_and_png_decoders() {
    let Some(ctx) = gpu_context("video gif/png") else { return };
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (2 * VIEW.width, VIEW.height + CAPTION_HEIGHT);
    let at0 = fixed_pixel(object_at(0));
    let at_end = fixed_pixel(object_at(N_FRAMES - 1));

    let gif_path = dir.path().join("out.gif");
    let v = write_video(&gif_path, &[episode()], ctx.clone(), VIEW).expect("gif");
    assert_eq!((v.format, v.frames), (VideoFormat::Gif, N_FRAMES));
    let mut options = gif::DecodeOptions::new();
    options.set_color_output(gif::ColorOutput::RGBA);
    let mut decoder = options.read_info(std::fs::File::open(&gif_path).unwrap()).unwrap();
    assert_eq!((decoder.width() as u32, decoder.height() as u32), (w, h));
    let mut images = Vec::new();
    while let Some(frame) = decoder.read_next_frame().unwrap() {
        assert_eq!((frame.width as u32, frame.height as u32, frame.left, frame.top), (w, h, 0, 0), "full frames");
        assert_eq!(frame.delay, 3, "1/30 s in hundredths");
        images.push(frame.buffer.to_vec());
    }
    assert_eq!(images.len(), N_FRAMES);
    assert!(is_object_color(rgb_at(&images[0], w, at0)) && !is_object_color(rgb_at(&images[0], w, at_end)));
    assert!(is_object_color(rgb_at(&images[N_FRAMES - 1], w, at_end)) && !is_object_color(rgb_at(&images[N_FRAMES - 1], w, at0)));

    // a folder (trailing /) of numbered PNG frames
    let png_dir = dir.path().join("frames/");
    let v = write_video(&png_dir, &[episode()], ctx, VIEW).expect("png frames");
    assert_eq!((v.format, v.frames), (VideoFormat::PngFrames, N_FRAMES));
    let mut names: Vec<String> = std::fs::read_dir(&png_dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    assert_eq!(names.len(), N_FRAMES, "{names:?}");
    assert_eq!((names[0].as_str(), names[N_FRAMES - 1].as_str()), ("frame_00000.png", "frame_00029.png"));
    for (k, at, away) in [(0, at0, at_end), (N_FRAMES - 1, at_end, at0)] {
        let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(png_dir.join(&names[k])).unwrap()));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height, info.color_type), (w, h, png::ColorType::Rgba));
        assert!(is_object_color(rgb_at(&buf, w, at)) && !is_object_color(rgb_at(&buf, w, away)), "PNG frame {k}");
    }
}

#[test]
fn bad_video_paths_are_one_line_errors_and_leave_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("out.avi");
    let e = format!("{:#}", VideoFormat::from_path(&bad).unwrap_err());
    assert!(e.contains("out.avi") && e.contains(".mp4") && !e.contains('\n'), "{e}");
    assert!("481x360".parse::<ViewSize>().is_err() && "0x0".parse::<ViewSize>().is_err() && "640x360".parse::<ViewSize>().is_ok());
    // a folder that cannot be made (under a file) names the path
    let file = dir.path().join("file");
    std::fs::write(&file, b"x").unwrap();
    let under = file.join("out.gif");
    let e = format!("{:#}", VideoWriter::create(&under, 32, 32, 30.0).err().expect("an error"));
    assert!(e.contains(&under.display().to_string()) && !e.contains('\n'), "{e}");
    // an odd size is refused for H.264; a writer dropped before finish leaves no file
    let e = format!("{:#}", VideoWriter::create(&dir.path().join("odd.mp4"), 33, 32, 30.0).err().expect("an error"));
    assert!(e.contains("odd.mp4") && e.contains("even"), "{e}");
    for name in ["dropped.mp4", "dropped.gif"] {
        let mut w = VideoWriter::create(&dir.path().join(name), 32, 32, 30.0).unwrap();
        w.push(&vec![128u8; 32 * 32 * 4]).unwrap();
        drop(w);
    }
    let left: Vec<String> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(left, vec!["file".to_string()], "nothing but the file the test made");
    // a frame of the wrong size is an error, not a panic
    let mut w = VideoWriter::create(&dir.path().join("ok.gif"), 32, 32, 30.0).unwrap();
    assert!(w.push(&[0u8; 16]).is_err());
    drop(w);
    // a path ending in .png: numbered frames beside it, STEM_00000.png, …
    let mut w = VideoWriter::create(&dir.path().join("shots/f.png"), 32, 32, 30.0).unwrap();
    assert_eq!(w.format(), VideoFormat::PngFrames);
    for k in 0..3u8 {
        w.push(&vec![k * 100; 32 * 32 * 4]).unwrap();
    }
    assert_eq!(w.finish().unwrap(), 3);
    let mut names: Vec<String> = std::fs::read_dir(dir.path().join("shots")).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    assert_eq!(names, ["f_00000.png", "f_00001.png", "f_00002.png"]);
}

/// Without any adapter (the Vulkan loader pointed at no driver), `--video` fails at once in one
/// line saying what it needs, before the replay runs and without writing anything.
#[test]
#[cfg(target_os = "linux")]
fn video_without_an_adapter_is_a_one_line_error_before_anything_runs() {
    let dir = tempfile::tempdir().unwrap();
    let video = dir.path().join("none.mp4");
    let out = Command::new(env!("CARGO_BIN_EXE_dextrain"))
        .args(["replay", "configs/grasp_lift.toml", "--traj", "configs/refs/grasp_lift.mcap", "--backend", "cpu", "--video"])
        .arg(&video)
        .env("VK_ICD_FILENAMES", dir.path().join("no-driver.json"))
        .env_remove("WGPU_BACKEND")
        .current_dir(ROOT)
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && e.contains("--video needs a wgpu adapter") && e.trim().lines().count() == 1, "{e}");
    assert!(out.stdout.is_empty(), "the replay did not run");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "nothing written");
}

/// `dextrain replay --video`: env 0's rollout, one frame per replayed frame.
#[test]
fn replay_video_has_a_frame_per_replayed_frame() {
    if gpu_context("replay --video").is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let video = dir.path().join("replay.mp4");
    let out = Command::new(env!("CARGO_BIN_EXE_dextrain"))
        .args(["replay", "configs/grasp_lift.toml", "--traj", "configs/refs/grasp_lift.mcap", "--backend", "cpu", "--video-size", "160x120", "--video"])
        .arg(&video)
        .current_dir(ROOT)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let frames = report["frames"].as_u64().unwrap();
    assert!(stderr.contains(&format!("({frames} frames, 320x148")), "{stderr}");
    if !python_av("replay --video") {
        return;
    }
    let r = read_with_pyav(&video, &[]);
    assert_eq!(r["frames"].as_u64(), Some(frames), "{r}");
}

#[test]
fn the_follow_camera_starts_on_the_object_and_eases_toward_it() {
    let mut follow = FollowTarget::new();
    let a = follow.update(Vec3::new(0.1, 0.0, 0.03));
    assert_eq!(a.target, Vec3::new(0.1, 0.0, 0.03));
    let b = follow.update(Vec3::new(0.2, 0.0, 0.03));
    assert!(b.target.x > 0.1 && b.target.x < 0.2, "{b:?}");
    // its view's centre is its target
    let (x, y) = b.project(b.target, 200, 100).unwrap();
    assert!((x - 100.0).abs() < 1e-3 && (y - 50.0).abs() < 1e-3, "{x} {y}");
    // points above the target are higher in the image (smaller rows)
    let (_, y_up) = b.project(b.target + Vec3::Z * 0.02, 200, 100).unwrap();
    assert!(y_up < y);
}

/// `dextrain eval RUN --video out.mp4`: a tiny trained run's first envs' episodes in one MP4 of
/// Σ episode lengths frames (each episode's frames: its reset state and every step but the last,
/// whose state is already the next episode's), and the image strip in the run's plots/; the same
/// on the GPU backend; `play --video` on the run's export.
#[test]
fn eval_video_writes_an_mp4_of_the_episodes_and_the_strip() {
    if gpu_context("eval --video").is_none() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path().to_str().unwrap();
    let sets = ["sim.backend=cpu", "train.device=cpu", "sim.num_envs=2", "task.episode_length=5", "train.iterations=1", "train.steps_per_env=4", "policy.actor_hidden=[8]", "policy.critic_hidden=[8]"];
    let mut args = vec!["train", "configs/lift_cube_cpu.toml", "--name", "vid", "--runs-dir", runs, "--quiet"];
    for s in &sets {
        args.extend(["--set", s]);
    }
    let run = |args: &[&str]| Command::new(env!("CARGO_BIN_EXE_dextrain")).args(args).current_dir(ROOT).output().unwrap();
    let out = run(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let dir = tmp.path().join("vid");
    let video = dir.join("eval/video.mp4");
    let out = run(&["eval", dir.to_str().unwrap(), "--episodes", "3", "--video", video.to_str().unwrap(), "--video-episodes", "2", "--video-size", "160x120"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let strip = dir.join("plots/eval_strip.png");
    assert!(stderr.contains(video.to_str().unwrap()) && stderr.contains(strip.to_str().unwrap()), "the summary names the video and the strip: {stderr}");
    assert!(!stderr.contains("OpenH264") && !stderr.lines().any(|l| l.starts_with("error:")), "no encoder chatter or errors: {stderr}");
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("eval/eval_it1_seed1000003_n3.json")).unwrap()).unwrap();
    let lengths: Vec<u64> = report["per_episode"].as_array().unwrap().iter().map(|r| r["length"].as_u64().unwrap()).collect();
    assert!(lengths.iter().all(|&l| l == lengths[0]), "episodes of one length (no early termination in 5 steps): {lengths:?}");
    let expected = 2 * lengths[0];
    let (w, h) = (320, 120 + CAPTION_HEIGHT);
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&strip).unwrap()));
    let info = decoder.read_info().unwrap().info().clone();
    assert_eq!((info.width, info.height), strip_size(2, w, h), "two rows (episodes) of two half-size frames");
    // a bad video path fails before anything runs, in one line naming it
    let out = run(&["eval", dir.to_str().unwrap(), "--episodes", "1", "--video", "x.webm"]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && e.contains("x.webm") && e.trim().lines().count() == 1, "{e}");
    let out = run(&["eval", dir.to_str().unwrap(), "--episodes", "1", "--video", "x.mp4", "--video-episodes", "0"]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && e.contains("--video-episodes 0") && e.trim().lines().count() == 1, "{e}");
    // the envs on a GPU (lavapipe here): the video renders on the eval's own device
    let gif = dir.join("eval/gpu.gif");
    let out = run(&["eval", dir.to_str().unwrap(), "--episodes", "1", "--backend", "gpu:llvmpipe", "--video", gif.to_str().unwrap(), "--video-size", "64x48"]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && e.contains("llvmpipe"), "{e}");
    let decoder = gif::DecodeOptions::new().read_info(std::fs::File::open(&gif).unwrap()).unwrap();
    assert_eq!((decoder.width(), decoder.height()), (128, 48 + CAPTION_HEIGHT as u16));
    // play --video on the run's export: one episode, a GIF frame per step of it
    let out = run(&["export", dir.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let played = dir.join("export/play.gif");
    let out = run(&["play", dir.join("export/policy.json").to_str().unwrap(), "--episodes", "1", "--episodes-json", "--video", played.to_str().unwrap(), "--video-size", "64x48"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let length = report["per_episode"][0]["length"].as_u64().unwrap();
    let mut decoder = gif::DecodeOptions::new().read_info(std::fs::File::open(&played).unwrap()).unwrap();
    let mut frames = 0;
    while decoder.read_next_frame().unwrap().is_some() {
        frames += 1;
    }
    assert_eq!(frames, length, "play's video: a frame per step of its episode");
    if !python_av("eval --video") {
        return;
    }
    let r = read_with_pyav(&video, &[]);
    assert_eq!(r["codec"], "h264", "{r}");
    assert_eq!((r["width"].as_u64(), r["height"].as_u64()), (Some(w as u64), Some(h as u64)), "{r}");
    assert_eq!(r["frames"].as_u64(), Some(expected), "Σ of the 2 filmed episodes' lengths: {r}");
}
