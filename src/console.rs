//! The run's console output. A run must never stop because its output is gone: with
//! `dextrain train … 2>&1 | head -1` the pipe closes after the first line, and Rust binaries ignore
//! SIGPIPE, so each later write returns EPIPE, which `eprintln!`/`println!` turn into a panic. These
//! functions write whole lines and drop write errors; the progress bar (indicatif) already ignores
//! its draw errors.

use std::io::Write;

/// Writes one line to stderr (progress and status), ignoring write errors.
pub fn status(line: &str) {
    let mut err = std::io::stderr().lock();
    // one write of the whole line (see `result`)
    let _ = err.write_all(format!("{line}\n").as_bytes());
}

/// Writes one warning line to stderr, ignoring write errors.
pub fn warn(line: &str) {
    status(line);
}

/// Writes one line to stdout (a command's machine-readable result), ignoring write errors.
pub fn result(line: &str) {
    let mut out = std::io::stdout().lock();
    // one write of the whole line: `writeln!` writes the line and its newline apart, and a long
    // line leaves stdout's buffer in pieces that an MPI launcher merging its ranks' output into one
    // stream interleaves with another rank's
    let _ = out.write_all(format!("{line}\n").as_bytes());
    let _ = out.flush();
}
