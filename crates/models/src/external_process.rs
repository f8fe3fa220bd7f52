//! A simulator process's pipes, read with bounds: whatever a process
//! writes, a line is held to the longest answer the protocol has and its
//! standard error to its last few lines, so a process that writes without
//! end is ended and named instead of filling the memory.

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStderr, ChildStdin, ChildStdout};
use std::sync::mpsc::{Receiver, RecvTimeoutError, sync_channel};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// How many lines of a process's standard error an error message quotes.
const STDERR_LINES: usize = 5;

/// How much of one line of a process's standard error is kept (the rest
/// of a longer line is read and dropped, so a flood takes no memory).
const STDERR_LINE_BYTES: usize = 1000;

/// Lines of standard output read ahead of the protocol: a process that
/// writes faster than its answers are read waits on its pipe.
const LINES_AHEAD: usize = 4096;

/// The longest line a process may write on standard output: a sample's
/// numbers (an f64 in text takes at most 24 characters), or an error
/// message, with room to spare. A longer line ends the process.
fn longest_line(signals: usize) -> usize {
    64 * 1024 + 64 * signals
}

/// What [`read_line_within`] found.
#[derive(Debug, PartialEq)]
enum LineRead {
    /// A whole line (its end, or the stream's end after some bytes).
    Line,
    /// A line longer than the limit: `line` holds its first `limit` bytes.
    TooLong,
    /// The stream ended.
    End,
}

/// Read one line into `line` (without its newline), keeping at most
/// `limit` bytes: at the limit it stops and says so (`drain` false), or
/// reads the rest of the line without keeping it (`drain` true). Memory
/// stays bounded whatever the process writes.
fn read_line_within(
    reader: &mut impl BufRead,
    limit: usize,
    drain: bool,
    line: &mut Vec<u8>,
) -> std::io::Result<LineRead> {
    line.clear();
    let mut cut = false;
    loop {
        let available = reader.fill_buf()?;
        if available.is_empty() {
            return Ok(match (line.is_empty() && !cut, cut) {
                (true, _) => LineRead::End,
                (false, true) => LineRead::TooLong,
                (false, false) => LineRead::Line,
            });
        }
        let (chunk, ends) = match available.iter().position(|b| *b == b'\n') {
            Some(at) => (&available[..at], Some(at + 1)),
            None => (available, None),
        };
        let room = limit.saturating_sub(line.len());
        line.extend_from_slice(&chunk[..chunk.len().min(room)]);
        let used = ends.unwrap_or(chunk.len());
        if chunk.len() > room {
            cut = true;
            if !drain {
                reader.consume(room);
                return Ok(LineRead::TooLong);
            }
        }
        reader.consume(used);
        if ends.is_some() {
            if line.last() == Some(&b'\r') {
                line.pop();
            }
            return Ok(if cut {
                LineRead::TooLong
            } else {
                LineRead::Line
            });
        }
    }
}

/// One running simulator process.
#[derive(Debug)]
pub(crate) struct Process {
    pub(crate) child: Child,
    stdin: ChildStdin,
    /// Its standard output's lines, or why reading stopped.
    lines: Receiver<std::result::Result<String, String>>,
    stderr: Arc<Mutex<VecDeque<String>>>,
}

impl Process {
    /// The process `child` with its pipes: its standard output read line
    /// by line (each at most [`longest_line`] of `signals`) and at most
    /// [`LINES_AHEAD`] lines ahead, its standard error's last lines kept
    /// (each cut to [`STDERR_LINE_BYTES`]), each on a thread of its own.
    pub(crate) fn attach(
        child: Child,
        stdin: ChildStdin,
        stdout: ChildStdout,
        stderr: ChildStderr,
        signals: usize,
    ) -> Self {
        let (sender, lines) = sync_channel(LINES_AHEAD);
        let limit = longest_line(signals);
        std::thread::spawn(move || {
            let mut reader = BufReader::new(stdout);
            let mut bytes = Vec::new();
            loop {
                let message = match read_line_within(&mut reader, limit, false, &mut bytes) {
                    Ok(LineRead::Line) => Ok(String::from_utf8_lossy(&bytes).into_owned()),
                    Ok(LineRead::TooLong) => Err(format!(
                        "it wrote a line longer than {limit} bytes (no answer of the protocol \
                         is that long), starting {:?}",
                        String::from_utf8_lossy(&bytes[..bytes.len().min(80)])
                    )),
                    Ok(LineRead::End) | Err(_) => break,
                };
                let stop = message.is_err();
                if sender.send(message).is_err() || stop {
                    break;
                }
            }
        });
        let tail = Arc::new(Mutex::new(VecDeque::with_capacity(STDERR_LINES)));
        let writer = Arc::clone(&tail);
        std::thread::spawn(move || {
            let mut reader = BufReader::new(stderr);
            let mut bytes = Vec::new();
            loop {
                let cut = match read_line_within(&mut reader, STDERR_LINE_BYTES, true, &mut bytes) {
                    Ok(LineRead::Line) => false,
                    Ok(LineRead::TooLong) => true,
                    Ok(LineRead::End) | Err(_) => break,
                };
                let mut line = String::from_utf8_lossy(&bytes).into_owned();
                if cut {
                    line.push_str(" [...]");
                }
                let mut tail = writer.lock().unwrap_or_else(PoisonError::into_inner);
                if tail.len() == STDERR_LINES {
                    tail.pop_front();
                }
                tail.push_back(line);
            }
        });
        Self {
            child,
            stdin,
            lines,
            stderr: tail,
        }
    }

    /// Write `text` to its standard input.
    pub(crate) fn send(&mut self, text: &str) -> std::result::Result<(), String> {
        self.stdin
            .write_all(text.as_bytes())
            .and_then(|()| self.stdin.flush())
            .map_err(|e| format!("it stopped reading its input ({e})"))
    }

    /// The next line within `timeout`.
    pub(crate) fn line(&mut self, timeout: Duration) -> std::result::Result<String, String> {
        self.line_by(Instant::now() + timeout, timeout)
    }

    /// The next line, if it comes before `deadline`, the end of a
    /// `timeout` that started earlier.
    pub(crate) fn line_by(
        &mut self,
        deadline: Instant,
        timeout: Duration,
    ) -> std::result::Result<String, String> {
        let left = deadline.saturating_duration_since(Instant::now());
        match self.lines.recv_timeout(left) {
            Ok(line) => line,
            Err(RecvTimeoutError::Timeout) => Err(format!(
                "no answer within {} s (the timeout)",
                timeout.as_secs_f64()
            )),
            Err(RecvTimeoutError::Disconnected) => {
                let status = self
                    .child
                    .wait()
                    .map_or_else(|e| e.to_string(), |s| s.to_string());
                Err(format!("it ended ({status})"))
            }
        }
    }

    pub(crate) fn stderr_tail(&self) -> String {
        let tail = self.stderr.lock().unwrap_or_else(PoisonError::into_inner);
        tail.iter().cloned().collect::<Vec<_>>().join(" | ")
    }

    pub(crate) fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every line of `text` read through a reader of `capacity` bytes.
    fn all_lines(
        text: &[u8],
        capacity: usize,
        limit: usize,
        drain: bool,
    ) -> Vec<(LineRead, String)> {
        let mut reader = BufReader::with_capacity(capacity, text);
        let mut line = Vec::new();
        let mut found = Vec::new();
        loop {
            let read = read_line_within(&mut reader, limit, drain, &mut line).unwrap();
            if read == LineRead::End {
                return found;
            }
            let stop = read == LineRead::TooLong && !drain;
            found.push((read, String::from_utf8(line.clone()).unwrap()));
            if stop {
                return found;
            }
        }
    }

    #[test]
    fn lines_are_read_whole_within_the_limit_whatever_the_buffer() {
        let text = b"record 0\r\n1.5 2.5\n\nlast without newline";
        for capacity in [1, 3, 7, 64] {
            let lines = all_lines(text, capacity, 100, false);
            let expected = ["record 0", "1.5 2.5", "", "last without newline"];
            assert_eq!(lines.len(), 4, "{capacity}: {lines:?}");
            for ((read, line), want) in lines.iter().zip(expected) {
                assert_eq!((read, line.as_str()), (&LineRead::Line, want), "{capacity}");
            }
        }
    }

    #[test]
    fn a_longer_line_stops_the_reader_or_is_cut_and_skipped() {
        let text = b"short\n0123456789abcdef\nnext\n";
        for capacity in [1, 4, 64] {
            // Standard output: the long line ends the reading at its limit.
            let stopped = all_lines(text, capacity, 10, false);
            assert_eq!(
                stopped,
                [
                    (LineRead::Line, "short".to_string()),
                    (LineRead::TooLong, "0123456789".to_string())
                ],
                "{capacity}"
            );
            // Standard error: cut, its rest skipped, the next line read.
            let drained = all_lines(text, capacity, 10, true);
            assert_eq!(
                drained,
                [
                    (LineRead::Line, "short".to_string()),
                    (LineRead::TooLong, "0123456789".to_string()),
                    (LineRead::Line, "next".to_string())
                ],
                "{capacity}"
            );
        }
    }

    #[test]
    fn an_endless_line_takes_no_more_than_the_limit() {
        // A gigabyte of one line, never held: the reader stops at the
        // limit, or drains it holding the limit only.
        use std::io::Read;
        let endless = std::io::repeat(b'7').take(1 << 30);
        let mut reader = BufReader::new(endless);
        let mut line = Vec::new();
        let read = read_line_within(&mut reader, 4096, false, &mut line).unwrap();
        assert_eq!((read, line.len()), (LineRead::TooLong, 4096));
        assert!(line.capacity() < 1 << 20);
        let long = std::io::repeat(b'7').take(1 << 24);
        let mut reader = BufReader::new(long.chain(&b"\nafter\n"[..]));
        let read = read_line_within(&mut reader, 100, true, &mut line).unwrap();
        assert_eq!((read, line.len()), (LineRead::TooLong, 100));
        read_line_within(&mut reader, 100, true, &mut line).unwrap();
        assert_eq!(line, b"after");
    }
}
