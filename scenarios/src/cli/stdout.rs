//! What the offline commands print on standard output. A reader that stops reading (`sgm match
//! a.json b.json | head -c 100`) is not an error of ours: the rest is dropped quietly, where
//! `println!` would panic (Rust ignores SIGPIPE, so the write fails with `BrokenPipe`). Any
//! other write error is reported on standard error once.

use std::io::{ErrorKind, Write};

/// Writes `text` and a newline to standard output; false only when it could not be written for
/// another reason than a closed pipe (said on standard error, naming `command`).
pub fn emit(command: &str, text: &str) -> bool {
    emit_text(command, &format!("{text}\n"))
}

/// Writes `text` as it is (see [`emit`]).
pub fn emit_text(command: &str, text: &str) -> bool {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => true,
        Err(e) if e.kind() == ErrorKind::BrokenPipe => true,
        Err(e) => {
            eprintln!("sgm {command}: cannot write to standard output: {e}");
            false
        }
    }
}
