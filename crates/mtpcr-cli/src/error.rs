//! The CLI's one failure type and its stdout writer. Every failure becomes `error: <message>`
//! on stderr and exit code 1 (clap's usage errors keep exit code 2).

use std::fmt;
use std::io::Write;

/// A failure to report to the user: a message that names the file, field or folder at fault.
#[derive(Debug)]
pub struct Failure(pub String);

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl From<mtpcr_core::Error> for Failure {
    fn from(e: mtpcr_core::Error) -> Self {
        Failure(e.to_string())
    }
}

impl From<String> for Failure {
    fn from(s: String) -> Self {
        Failure(s)
    }
}

impl From<&str> for Failure {
    fn from(s: &str) -> Self {
        Failure(s.to_string())
    }
}

/// Result of a CLI step.
pub type CliResult<T> = Result<T, Failure>;

/// Writes one line to stdout. A closed pipe (`mtpcr ... | head -1`) is ignored so the run
/// still finishes and writes its files; any other write error ends the program with code 1.
pub fn write_stdout(args: fmt::Arguments<'_>) {
    let mut out = std::io::stdout().lock();
    if let Err(e) = writeln!(out, "{args}").and_then(|_| out.flush()) {
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            eprintln!("error: cannot write to standard output: {e}");
            std::process::exit(1);
        }
    }
}

/// `println!` through [`write_stdout`].
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::error::write_stdout(format_args!($($arg)*))
    };
}
pub(crate) use outln;
