//! The `tracery` command line: render, stats and bench (and, with the `viewer` feature, the
//! interactive viewer).

mod cli;

use std::process::ExitCode;

fn main() -> ExitCode {
    // Rust ignores SIGPIPE, so a print after the reader of a pipe has gone panics; with the
    // signal's default the process ends quietly, as `cat` or `grep` do.
    sigpipe::reset();
    let args = cli::parse();
    match cli::run(args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
