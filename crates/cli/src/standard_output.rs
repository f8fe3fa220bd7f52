//! Standard output whose write errors say where they happened: "No space
//! left on device" alone does not tell a user which of a command's
//! outputs was full or closed.

use std::io::{self, Write};

/// The process's standard output, locked; every write error names it.
pub(crate) struct StandardOutput(io::StdoutLock<'static>);

impl StandardOutput {
    pub(crate) fn lock() -> Self {
        Self(io::stdout().lock())
    }

    /// Write `text` whole and flush it, so that an error reaches the
    /// caller instead of being dropped with the buffer.
    pub(crate) fn write_text(text: &str) -> io::Result<()> {
        let mut out = Self::lock();
        out.write_all(text.as_bytes())?;
        out.flush()
    }
}

/// The error with where it happened; its kind is kept (a closed pipe
/// stays a closed pipe, which `twostage ... | head` does not report).
fn named(e: io::Error) -> io::Error {
    io::Error::new(
        e.kind(),
        format!(
            "writing to standard output: {e} (redirect it to a file with room, or use --out where the command has it)"
        ),
    )
}

impl Write for StandardOutput {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.0.write(buf).map_err(named)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.0.flush().map_err(named)
    }
}
