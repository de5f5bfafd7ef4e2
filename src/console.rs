//! The run's console output. A run must never stop because its output is gone: with
//! `dextrain train … 2>&1 | head -1` the pipe closes after the first line, and Rust binaries ignore
//! SIGPIPE, so each later write returns EPIPE, which `eprintln!`/`println!` turn into a panic. These
//! functions write whole lines and drop write errors; the progress bar (indicatif) already ignores
//! its draw errors.

use std::io::Write;

/// Writes one line to stderr (progress and status), ignoring write errors.
pub fn status(line: &str) {
    let mut err = std::io::stderr().lock();
    let _ = writeln!(err, "{line}");
}

/// Writes one warning line to stderr, ignoring write errors.
pub fn warn(line: &str) {
    status(line);
}

/// Writes one line to stdout (a command's machine-readable result), ignoring write errors.
pub fn result(line: &str) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}
