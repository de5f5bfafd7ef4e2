//! Metrics logging (src/metrics.rs, src/tensorboard.rs, src/plot.rs): CRC-32C check values, event
//! files read back by our reader and by TensorBoard's own `EventAccumulator` (Python, when installed),
//! the metrics.csv round trip and resume, and the learning-curve PNG.

use std::path::{Path, PathBuf};
use std::process::Command;

use dextrain::metrics::{MetricsLog, event_files, read_csv};
use dextrain::plot::{GRID_COLUMNS, PANEL_HEIGHT, PANEL_WIDTH, grid_size, panel_titles, plot_run};
use dextrain::tensorboard::{EventWriter, crc32c, masked_crc32c, read_scalars};

fn cols(names: &[&str]) -> Vec<String> {
    names.iter().map(|s| s.to_string()).collect()
}

/// Floats compared by bits, so NaN == NaN and -0.0 != 0.0.
fn same64(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
}

fn same32(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// The only event file of a run directory.
fn only_event_file(dir: &Path) -> PathBuf {
    let files = event_files(dir).unwrap();
    assert_eq!(files.len(), 1, "expected one event file in {}: {files:?}", dir.display());
    files.into_iter().next().unwrap()
}

/// The scalars a set of CSV rows must produce: (column, iteration, value as f32), row by row.
fn expected_scalars(columns: &[String], rows: &[(u64, Vec<f64>)]) -> Vec<(String, i64, f32)> {
    let mut out = Vec::new();
    for (it, values) in rows {
        for (c, v) in columns.iter().zip(values) {
            out.push((c.clone(), *it as i64, *v as f32));
        }
    }
    out
}

fn assert_scalars_eq(got: &[(String, i64, f32)], want: &[(String, i64, f32)]) {
    assert_eq!(got.len(), want.len(), "scalar count");
    for (g, w) in got.iter().zip(want) {
        assert!(g.0 == w.0 && g.1 == w.1 && same32(g.2, w.2), "scalar {g:?} != {w:?}");
    }
}

// ---------------------------------------------------------------------------------------------
// CRC-32C

#[test]
fn crc32c_check_values() {
    assert_eq!(crc32c(b"123456789"), 0xE306_9283); // the standard CRC-32C check value
    assert_eq!(crc32c(b""), 0);
    // masked values, computed by TensorBoard's own masked_crc32c
    assert_eq!(masked_crc32c(b""), 0xA282_EAD8);
    assert_eq!(masked_crc32c(b"123456789"), 0xC78A_B0E5);
    // the length (24) of the file_version record every TensorFlow event file starts with
    assert_eq!(masked_crc32c(&24u64.to_le_bytes()), 0x224B_7FA3);
}

// ---------------------------------------------------------------------------------------------
// Event files

/// Scalars with awkward values and steps: NaN, ±inf, -0, subnormal, negative and huge steps.
fn awkward_scalars() -> Vec<(String, i64, f32)> {
    vec![
        ("reward/mean".into(), 0, 1.5),
        ("loss/value".into(), 0, -0.0),
        ("reward/mean".into(), 1, f32::NAN),
        ("lr".into(), 1, 3e-4),
        ("kl".into(), 2, f32::INFINITY),
        ("kl".into(), 3, f32::NEG_INFINITY),
        ("tiny".into(), 4, f32::from_bits(1)),
        ("negative step".into(), -7, 2.0),
        ("big step".into(), i64::MAX, f32::MAX),
        ("ünïcode/tag".into(), 5, -123.456),
    ]
}

fn write_events(dir: &Path, scalars: &[(String, i64, f32)]) -> PathBuf {
    let mut w = EventWriter::create(dir).unwrap();
    for (i, (tag, step, v)) in scalars.iter().enumerate() {
        w.add_scalar(tag, *step, *v, 1.7e9 + i as f64).unwrap();
    }
    w.flush().unwrap();
    w.path().to_path_buf()
}

#[test]
fn event_file_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let scalars = awkward_scalars();
    let path = write_events(dir.path(), &scalars);
    let name = path.file_name().unwrap().to_string_lossy().to_string();
    assert!(name.starts_with("events.out.tfevents.") && name.ends_with(".dextrain"), "{name}");
    assert!(name.contains(&format!(".{}.", std::process::id())), "{name} lacks the pid");

    let bytes = std::fs::read(&path).unwrap();
    // the file_version record is 24 bytes long, like TensorFlow's: the same first 12 bytes
    assert_eq!(&bytes[..12], &[0x18, 0, 0, 0, 0, 0, 0, 0, 0xA3, 0x7F, 0x4B, 0x22]);
    assert!(bytes.windows(13).any(|w| w == b"brain.Event:2"));

    assert_scalars_eq(&read_scalars(&path).unwrap(), &scalars);

    // a second writer in the same second never overwrites the first
    let second = EventWriter::create(dir.path()).unwrap();
    assert_ne!(second.path(), path.as_path());
    assert_scalars_eq(&read_scalars(&path).unwrap(), &scalars);
}

#[test]
fn corrupted_event_file_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_events(dir.path(), &awkward_scalars());
    let good = std::fs::read(&path).unwrap();
    let bad = dir.path().join("events.out.tfevents.bad");
    // every single corrupted byte (length, its CRC, data, data CRC of every record) is caught
    for i in 0..good.len() {
        for flip in [0x01u8, 0x80, 0xFF] {
            let mut b = good.clone();
            b[i] ^= flip;
            std::fs::write(&bad, &b).unwrap();
            let err = read_scalars(&bad).expect_err(&format!("byte {i} ^ {flip:#x} not detected"));
            let msg = format!("{err:#}");
            assert!(msg.contains("events.out.tfevents.bad") && !msg.contains('\n'), "{msg}");
        }
    }
    // a truncated file (a run killed mid-write) too
    for cut in [1, 5, 13, good.len() - 20, good.len() - 1] {
        std::fs::write(&bad, &good[..cut]).unwrap();
        assert!(read_scalars(&bad).is_err(), "truncation to {cut} bytes not detected");
    }
    let missing = dir.path().join("nope.tfevents");
    assert!(format!("{:#}", read_scalars(&missing).unwrap_err()).contains("nope.tfevents"));
}

/// Reads every scalar of an event file or run directory with TensorBoard's `EventAccumulator`:
/// tag -> [(step, f32 bits, wall_time)]. None (after printing why) when Python's `tensorboard` is
/// not installed; panics then if REQUIRE_PYTHON_TB=1 (CI).
fn tensorboard_scalars(test: &str, path: &Path) -> Option<serde_json::Value> {
    const SCRIPT: &str = r#"
import json, struct, sys
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
acc = EventAccumulator(sys.argv[1], size_guidance={"scalars": 0})
acc.Reload()
out = {}
for tag in acc.Tags()["scalars"]:
    out[tag] = [[e.step, struct.unpack("<I", struct.pack("<f", e.value))[0], e.wall_time] for e in acc.Scalars(tag)]
print(json.dumps(out))
"#;
    let required = std::env::var("REQUIRE_PYTHON_TB").is_ok_and(|v| v == "1");
    let probe = Command::new("python3").args(["-c", "import tensorboard"]).output();
    let why = match &probe {
        Ok(o) if o.status.success() => None,
        Ok(o) => {
            let err = String::from_utf8_lossy(&o.stderr);
            let last = err.lines().last().map_or_else(|| o.status.to_string(), str::to_string);
            Some(format!("python3 cannot import tensorboard ({last})"))
        }
        Err(e) => Some(format!("cannot run python3: {e}")),
    };
    if let Some(why) = why {
        if required {
            panic!("{test}: REQUIRE_PYTHON_TB=1 but {why} (pip install tensorboard)");
        }
        eprintln!("{test}: SKIPPED: {why} (pip install tensorboard to run it)");
        return None;
    }
    let out = Command::new("python3").args(["-c", SCRIPT]).arg(path).output().unwrap();
    assert!(out.status.success(), "{test}: EventAccumulator failed:\n{}", String::from_utf8_lossy(&out.stderr));
    Some(serde_json::from_slice(&out.stdout).unwrap())
}

/// (tag, step, value) triples of TensorBoard's answer, sorted like `sorted` sorts ours.
fn tb_triples(v: &serde_json::Value) -> Vec<(String, i64, u32, f64)> {
    let mut out = Vec::new();
    for (tag, events) in v.as_object().unwrap() {
        for e in events.as_array().unwrap() {
            let e = e.as_array().unwrap();
            out.push((tag.clone(), e[0].as_i64().unwrap(), e[1].as_u64().unwrap() as u32, e[2].as_f64().unwrap()));
        }
    }
    out.sort_by(|a, b| (&a.0, a.1).cmp(&(&b.0, b.1)));
    out
}

fn sorted(scalars: &[(String, i64, f32)]) -> Vec<(String, i64, u32)> {
    let mut out: Vec<_> = scalars.iter().map(|(t, s, v)| (t.clone(), *s, v.to_bits())).collect();
    out.sort_by(|a, b| (&a.0, a.1).cmp(&(&b.0, b.1)));
    out
}

fn canon_nan(bits: u32) -> u32 {
    if f32::from_bits(bits).is_nan() { f32::NAN.to_bits() } else { bits }
}

#[test]
fn tensorboard_reads_our_event_files() {
    let test = "tensorboard_reads_our_event_files";
    let dir = tempfile::tempdir().unwrap();
    // the awkward scalars, but with non-negative steps (TensorBoard purges steps that go backwards)
    let scalars: Vec<_> = awkward_scalars().into_iter().filter(|s| s.1 >= 0).collect();
    let path = write_events(dir.path(), &scalars);
    let Some(tb) = tensorboard_scalars(test, &path) else { return };
    let got: Vec<_> = tb_triples(&tb).into_iter().map(|(t, s, v, _)| (t, s, canon_nan(v))).collect();
    let want: Vec<_> = sorted(&scalars).into_iter().map(|(t, s, v)| (t, s, canon_nan(v))).collect();
    assert_eq!(got, want);

    // a whole run directory, resumed: TensorBoard sees exactly metrics.csv's rows, with the kept
    // rows' original wall times
    let run = dir.path().join("run");
    let columns = cols(&["reward/mean", "loss/value", "lr"]);
    let mut log = MetricsLog::create(&run, &columns).unwrap();
    for it in 0..6u64 {
        log.append(it, &[it as f64 * 0.5, 1.0 / (it as f64 + 1.0), 3e-4]).unwrap();
    }
    drop(log);
    let before = tb_triples(&tensorboard_scalars(test, &run).unwrap());
    std::thread::sleep(std::time::Duration::from_millis(20));
    let mut log = MetricsLog::resume(&run, &columns, 3).unwrap();
    log.append(4, &[-1.0, -2.0, 1e-4]).unwrap();
    drop(log);
    let after = tb_triples(&tensorboard_scalars(test, &run).unwrap());
    let (_, rows) = read_csv(&run.join("metrics.csv")).unwrap();
    let got: Vec<_> = after.iter().map(|(t, s, v, _)| (t.clone(), *s, *v)).collect();
    assert_eq!(got, sorted(&expected_scalars(&columns, &rows)));
    for (t, s, _, wall) in after.iter().filter(|a| a.1 <= 3) {
        let old = before.iter().find(|b| &b.0 == t && b.1 == *s).unwrap();
        assert_eq!(*wall, old.3, "{t} step {s}: wall time not kept across resume");
    }
}

// ---------------------------------------------------------------------------------------------
// metrics.csv

fn tricky_rows() -> Vec<(u64, Vec<f64>)> {
    vec![
        (0, vec![0.1, 1e-7, 3e300, -0.0]),
        (1, vec![f64::NAN, f64::INFINITY, f64::NEG_INFINITY, f64::MIN_POSITIVE]),
        (2, vec![1.0 / 3.0, -2.5e-310, 123456789.0, 5e-324]),
        (5, vec![0.0, 1.0, 2.0, 4096.0]),
    ]
}

#[test]
fn metrics_csv_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let columns = cols(&["reward/mean", "lr", "env_steps", "loss/value"]);
    let rows = tricky_rows();
    let runs = [dir.path().join("a"), dir.path().join("b")];
    for run in &runs {
        let mut log = MetricsLog::create(run, &columns).unwrap();
        for (it, v) in &rows {
            log.append(*it, v).unwrap();
        }
        // flushed after every row: readable while the log is still open
        let (c, r) = read_csv(&run.join("metrics.csv")).unwrap();
        assert_eq!(c, columns);
        assert_eq!(r.len(), rows.len());
        for ((it, v), (it2, v2)) in rows.iter().zip(&r) {
            assert!(it == it2 && same64(v, v2), "row {it}: wrote {v:?}, read {v2:?}");
        }
        assert_scalars_eq(&read_scalars(&only_event_file(run)).unwrap(), &expected_scalars(&columns, &rows));
    }
    let text = std::fs::read_to_string(runs[0].join("metrics.csv")).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "iteration,reward/mean,lr,env_steps,loss/value");
    assert!(lines[1].starts_with("0,0.1,0.0000001,3000000") && lines[1].ends_with(",-0"), "{}", lines[1]);
    assert!(lines[2].starts_with("1,nan,inf,-inf,0.0000") && lines[2].ends_with("22250738585072014"), "{}", lines[2]);
    assert_eq!(lines[4], "5,0,1,2,4096");
    // identical inputs, byte-identical files
    assert_eq!(text, std::fs::read_to_string(runs[1].join("metrics.csv")).unwrap());

    // a run is never overwritten
    let err = MetricsLog::create(&runs[0], &columns).err().expect("create over an existing run");
    assert!(format!("{err:#}").contains("metrics.csv"), "{err:#}");
    assert_eq!(text, std::fs::read_to_string(runs[0].join("metrics.csv")).unwrap());
}

#[test]
fn metrics_log_rejects_bad_rows_and_columns() {
    let dir = tempfile::tempdir().unwrap();
    let columns = cols(&["a", "b"]);
    let mut log = MetricsLog::create(dir.path(), &columns).unwrap();
    assert!(log.append(0, &[1.0]).is_err(), "too few values");
    assert!(log.append(0, &[1.0, 2.0, 3.0]).is_err(), "too many values");
    log.append(3, &[1.0, 2.0]).unwrap();
    assert!(log.append(3, &[1.0, 2.0]).is_err(), "repeated iteration");
    assert!(log.append(2, &[1.0, 2.0]).is_err(), "iteration going back");
    log.append(4, &[1.0, 2.0]).unwrap();
    let (_, rows) = read_csv(&dir.path().join("metrics.csv")).unwrap();
    assert_eq!(rows.iter().map(|r| r.0).collect::<Vec<_>>(), vec![3, 4]);

    for bad in [cols(&["a", "a"]), cols(&["iteration"]), cols(&["a,b"]), cols(&[""])] {
        let sub = dir.path().join("bad");
        assert!(MetricsLog::create(&sub, &bad).is_err(), "columns {bad:?} accepted");
    }
}

#[test]
fn read_csv_errors_name_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("metrics.csv");
    let cases = [
        ("iteration,a,b\n0,1,2\n1,1,x\n", "metrics.csv:3:"),
        ("iteration,a,b\n0,1,2\n1,1\n", "metrics.csv:3:"),
        ("iteration,a,b\n-1,1,2\n", "metrics.csv:2:"),
        ("step,a,b\n0,1,2\n", "metrics.csv:1:"),
        ("", "metrics.csv"),
    ];
    for (text, want) in cases {
        std::fs::write(&path, text).unwrap();
        let msg = format!("{:#}", read_csv(&path).expect_err(text));
        assert!(msg.contains(want) && !msg.contains('\n'), "{text:?}: {msg}");
    }
    let msg = format!("{:#}", read_csv(&dir.path().join("none.csv")).unwrap_err());
    assert!(msg.contains("none.csv") && !msg.contains('\n'), "{msg}");
}

#[test]
fn resume_truncates_rows_and_rewrites_events() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path();
    let columns = cols(&["reward/mean", "loss/value", "lr"]);
    let row = |it: u64| vec![it as f64 * 0.25, (it as f64).sqrt(), if it == 7 { f64::NAN } else { 1e-3 }];
    let mut log = MetricsLog::create(run, &columns).unwrap();
    for it in 0..10 {
        log.append(it, &row(it)).unwrap();
    }
    drop(log);
    let csv = run.join("metrics.csv");
    let full = std::fs::read_to_string(&csv).unwrap();
    // a second, stale event file (e.g. from an earlier resume) is deleted too
    write_events(run, &[("stale".into(), 99, 1.0)]);
    assert_eq!(event_files(run).unwrap().len(), 2);

    let mut log = MetricsLog::resume(run, &columns, 7).unwrap();
    let (_, rows) = read_csv(&csv).unwrap();
    let want: Vec<(u64, Vec<f64>)> = (0..=7).map(|it| (it, row(it))).collect();
    assert_eq!(rows.len(), want.len());
    for ((a, va), (b, vb)) in rows.iter().zip(&want) {
        assert!(a == b && same64(va, vb), "{a}: {va:?} != {vb:?}");
    }
    // the kept rows are byte-identical to what was first written
    let kept = std::fs::read_to_string(&csv).unwrap();
    assert!(full.starts_with(&kept) && kept.ends_with("\n") && kept.lines().count() == 9, "{kept}");
    let events = only_event_file(run);
    assert_eq!(log.event_file(), events.as_path());
    assert_scalars_eq(&read_scalars(&events).unwrap(), &expected_scalars(&columns, &want));

    // logging goes on after the checkpoint; an iteration at or before it is refused
    assert!(log.append(7, &row(7)).is_err());
    log.append(8, &[-1.0, -2.0, -3.0]).unwrap();
    drop(log);
    let mut want = want;
    want.push((8, vec![-1.0, -2.0, -3.0]));
    let (_, rows) = read_csv(&csv).unwrap();
    assert_eq!(rows.iter().map(|r| r.0).collect::<Vec<_>>(), (0..=8).collect::<Vec<_>>());
    assert_scalars_eq(&read_scalars(&only_event_file(run)).unwrap(), &expected_scalars(&columns, &want));

    // a torn last line (the run was killed while writing it) is dropped; resume past the end keeps all
    let mut text = std::fs::read_to_string(&csv).unwrap();
    text.push_str("9,1.5,0.");
    std::fs::write(&csv, &text).unwrap();
    drop(MetricsLog::resume(run, &columns, 100).unwrap());
    let (_, rows) = read_csv(&csv).unwrap();
    assert_eq!(rows.len(), 9);
    assert_scalars_eq(&read_scalars(&only_event_file(run)).unwrap(), &expected_scalars(&columns, &want));

    // resume(0) keeps only the first row
    drop(MetricsLog::resume(run, &columns, 0).unwrap());
    assert_eq!(read_csv(&csv).unwrap().1.len(), 1);
    assert_eq!(read_scalars(&only_event_file(run)).unwrap().len(), columns.len());
}

#[test]
fn resume_with_other_columns_is_a_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    let columns = cols(&["reward/mean", "lr"]);
    let mut log = MetricsLog::create(dir.path(), &columns).unwrap();
    log.append(0, &[1.0, 2.0]).unwrap();
    log.append(1, &[3.0, 4.0]).unwrap();
    drop(log);
    let csv = dir.path().join("metrics.csv");
    let before = std::fs::read(&csv).unwrap();
    let events_before = event_files(dir.path()).unwrap();
    for other in [cols(&["reward/mean"]), cols(&["lr", "reward/mean"]), cols(&["reward/mean", "lr", "kl"])] {
        let err = MetricsLog::resume(dir.path(), &other, 0).err().expect("resume with other columns");
        let msg = format!("{err:#}");
        assert!(msg.contains(&csv.display().to_string()) && !msg.contains('\n'), "{msg}");
    }
    // nothing was touched
    assert_eq!(std::fs::read(&csv).unwrap(), before);
    assert_eq!(event_files(dir.path()).unwrap(), events_before);
    // no metrics.csv at all
    let err = MetricsLog::resume(&dir.path().join("nope"), &columns, 0).err().unwrap();
    assert!(format!("{err:#}").contains("metrics.csv"), "{err:#}");
}

// ---------------------------------------------------------------------------------------------
// Plots

/// CRC-32 (IEEE, PNG's) of `data`.
fn crc32(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

/// Checks the PNG's signature and chunk structure (every chunk's CRC, IHDR first, IEND last, IDAT
/// present) and returns the IHDR (width, height).
fn png_size(path: &Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap();
    assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "{}: not a PNG", path.display());
    let mut pos = 8;
    let mut names = Vec::new();
    let mut size = (0, 0);
    while pos < b.len() {
        let len = u32::from_be_bytes(b[pos..pos + 4].try_into().unwrap()) as usize;
        let kind = &b[pos + 4..pos + 8];
        let data = &b[pos + 8..pos + 8 + len];
        let crc = u32::from_be_bytes(b[pos + 8 + len..pos + 12 + len].try_into().unwrap());
        assert_eq!(crc32(&b[pos + 4..pos + 8 + len]), crc, "chunk {} CRC", String::from_utf8_lossy(kind));
        if kind == b"IHDR" {
            size =
                (u32::from_be_bytes(data[..4].try_into().unwrap()), u32::from_be_bytes(data[4..8].try_into().unwrap()));
        }
        names.push(String::from_utf8_lossy(kind).to_string());
        pos += 12 + len;
    }
    assert_eq!(pos, b.len());
    assert_eq!(names.first().map(String::as_str), Some("IHDR"));
    assert_eq!(names.last().map(String::as_str), Some("IEND"));
    assert!(names.iter().any(|n| n == "IDAT"));
    size
}

/// If Python's PIL is installed, decodes the PNG and returns (width, height, distinct colours).
fn pil_decode(path: &Path) -> Option<(u32, u32, u64)> {
    let script = "import sys; from PIL import Image; im = Image.open(sys.argv[1]); im.load(); \
                  print(im.size[0], im.size[1], len(im.convert('RGB').getcolors(1 << 24)))";
    let out = Command::new("python3").args(["-c", script]).arg(path).output().ok()?;
    if !out.status.success() {
        eprintln!("png decode with PIL skipped: {}", String::from_utf8_lossy(&out.stderr).trim());
        return None;
    }
    let text = String::from_utf8(out.stdout).unwrap();
    let v: Vec<u64> = text.split_whitespace().map(|s| s.parse().unwrap()).collect();
    Some((v[0] as u32, v[1] as u32, v[2]))
}

/// A run with every column the trainer logs, `n` iterations, a few NaNs.
fn write_full_run(dir: &Path, n: u64) -> Vec<String> {
    let columns = cols(&[
        "env_steps",
        "fps",
        "time_s",
        "reward/mean",
        "episode/length",
        "episode/success_rate",
        "episode/return",
        "reward/tracking",
        "reward/action_rate",
        "reward/contact",
        "loss/surrogate",
        "loss/value",
        "loss/entropy",
        "lr",
        "kl",
        "policy/std",
    ]);
    let mut log = MetricsLog::create(dir, &columns).unwrap();
    for it in 0..n {
        let t = it as f64;
        let mut v: Vec<f64> = vec![
            (it + 1) as f64 * 24576.0,
            50_000.0 + 1000.0 * (t * 0.3).sin(),
            t * 0.5,
            (t / 10.0).tanh(),
            100.0 + t,
            (t / 50.0).min(1.0),
            10.0 * (t / 10.0).tanh(),
            0.5 * (t / 7.0).tanh(),
            -0.01 * (1.0 + (t * 0.7).cos()),
            0.1 + 0.05 * (t * 0.2).sin(),
            -0.02 / (1.0 + t),
            1.0 / (1.0 + 0.1 * t),
            -0.01,
            3e-4 * 0.97f64.powf(t),
            0.01 * (1.0 + (t * 0.5).sin()),
            (-t / 40.0).exp(),
        ];
        if it == 5 {
            v[3] = f64::NAN; // a gap in the mean reward
            v[13] = f64::INFINITY;
        }
        log.append(it, &v).unwrap();
    }
    columns
}

#[test]
fn plot_run_writes_a_grid_png() {
    let dir = tempfile::tempdir().unwrap();
    write_full_run(dir.path(), 40);
    let out = dir.path().join("plots");
    let written = plot_run(&dir.path().join("metrics.csv"), &out).unwrap();
    assert_eq!(written, vec![out.join("learning_curves.png")]);
    // 12 panels: mean reward, episode return, success rate, episode length, reward terms, the two
    // losses, learning rate, KL, entropy, policy std, fps
    let want = (GRID_COLUMNS * PANEL_WIDTH, 4 * PANEL_HEIGHT);
    assert_eq!(grid_size(12), want);
    assert_eq!(png_size(&written[0]), want);
    if let Some((w, h, colours)) = pil_decode(&written[0]) {
        assert_eq!((w, h), want);
        assert!(colours > 20, "only {colours} colours: nothing drawn?");
    }
    // no temporary left behind
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), 1);
    // plotting again replaces the file
    assert_eq!(plot_run(&dir.path().join("metrics.csv"), &out).unwrap(), written);
}

/// Issue 40: each loss on a panel (and a y scale) of its own, so PPO's surrogate (~0.01) is not a
/// flat line under its value loss (~100s), nor distillation's action loss under its latent loss;
/// the reference kinds' tracking errors plotted.
#[test]
fn each_loss_has_its_own_panel_and_tracking_errors_are_plotted() {
    let ppo = cols(&["reward/mean", "loss/surrogate", "loss/value", "loss/entropy", "lr"]);
    assert_eq!(panel_titles(&ppo), ["mean reward", "loss: surrogate", "loss: value", "learning rate (log)", "entropy"]);
    let distill = cols(&["loss/action", "loss/latent"]);
    assert_eq!(panel_titles(&distill), ["loss: action", "loss: latent"]);
    let track = cols(&["episode/success_rate", "tracking/obj_pos_err_m", "tracking/obj_rot_err_deg"]);
    assert_eq!(panel_titles(&track), ["success rate", "object error against the reference (m)", "object error against the reference (deg)"]);
    // a reference run's columns as the runner writes them, drawn
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("metrics.csv");
    std::fs::write(&csv, "iteration,loss/surrogate,loss/value,tracking/obj_pos_err_m,tracking/obj_rot_err_deg\n1,0.01,300,0.03,12\n2,-0.02,150,0.02,9\n").unwrap();
    let written = plot_run(&csv, &dir.path().join("p")).unwrap();
    assert_eq!(png_size(&written[0]), (GRID_COLUMNS * PANEL_WIDTH, 2 * PANEL_HEIGHT));
}

#[test]
fn plot_run_skips_absent_columns() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("metrics.csv");
    // two panels (fps, lr), x = iteration, one row only, a non-positive lr on the log axis
    std::fs::write(&csv, "iteration,fps,lr,time_s\n0,1000,0,0.5\n").unwrap();
    let written = plot_run(&csv, &dir.path().join("p")).unwrap();
    assert_eq!(png_size(&written[0]), (2 * PANEL_WIDTH, PANEL_HEIGHT));
    // a header only: empty panels
    std::fs::write(&csv, "iteration,reward/mean,reward/a,reward/b,loss/value\n").unwrap();
    let written = plot_run(&csv, &dir.path().join("q")).unwrap();
    assert_eq!(png_size(&written[0]), (GRID_COLUMNS * PANEL_WIDTH, PANEL_HEIGHT));
    // every value non-finite
    std::fs::write(&csv, "iteration,kl,episode/length,policy/std,reward/x\n0,nan,inf,-inf,nan\n1,nan,nan,nan,nan\n")
        .unwrap();
    let written = plot_run(&csv, &dir.path().join("r")).unwrap();
    assert_eq!(png_size(&written[0]), (GRID_COLUMNS * PANEL_WIDTH, 2 * PANEL_HEIGHT));
}

#[test]
fn plot_run_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing/metrics.csv");
    let msg = format!("{:#}", plot_run(&missing, &dir.path().join("p")).unwrap_err());
    assert!(msg.contains("missing/metrics.csv") && !msg.contains('\n'), "{msg}");
    let csv = dir.path().join("metrics.csv");
    std::fs::write(&csv, "iteration,time_s,something\n0,1,2\n").unwrap();
    let msg = format!("{:#}", plot_run(&csv, &dir.path().join("p")).unwrap_err());
    assert!(msg.contains("metrics.csv") && !msg.contains('\n'), "{msg}");
    assert!(!dir.path().join("p").join("learning_curves.png").exists());
}
