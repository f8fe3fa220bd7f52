//! An instance's log: FMI's log callbacks end here, and an error quotes
//! the last lines.

use std::collections::VecDeque;
use std::ffi::{CStr, c_char, c_int, c_void};
use std::sync::{Mutex, PoisonError};

/// How many of an instance's last log messages an error quotes.
const LOG_LINES: usize = 8;

/// The messages an instance logged, the last [`LOG_LINES`] of them.
#[derive(Debug, Default)]
pub(crate) struct Log {
    lines: Mutex<VecDeque<String>>,
}

impl Log {
    pub(super) fn push(&self, line: String) {
        let mut lines = self.lines.lock().unwrap_or_else(PoisonError::into_inner);
        if lines.len() == LOG_LINES {
            lines.pop_front();
        }
        lines.push_back(line);
    }

    pub(super) fn take(&self) -> Vec<String> {
        let mut lines = self.lines.lock().unwrap_or_else(PoisonError::into_inner);
        lines.drain(..).collect()
    }

    pub(super) fn clear(&self) {
        self.lines
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clear();
    }
}

fn text(pointer: *const c_char) -> String {
    if pointer.is_null() {
        String::new()
    } else {
        // SAFETY: the FMU passes a NUL-terminated string valid for the call.
        unsafe { CStr::from_ptr(pointer) }
            .to_string_lossy()
            .into_owned()
    }
}

/// The sink of every FMU message: FMI 3.0's log callback itself, and the
/// end of FMI 2.0's variadic logger (src/logger.c). `environment` is the
/// instance's [`Log`].
///
/// # Safety
/// `environment` is null or the `Log` an instance was created with, alive;
/// `category` and `message` are null or NUL-terminated strings, as FMI
/// promises of its callers.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn twostage_fmi_log(
    environment: *mut c_void,
    status: c_int,
    category: *const c_char,
    message: *const c_char,
) {
    if environment.is_null() {
        return;
    }
    // SAFETY: every instance is created with its own boxed Log as the
    // environment, and the Log outlives the instance.
    let log = unsafe { &*(environment as *const Log) };
    let category = text(category);
    let message = text(message);
    let message = message.trim_end();
    log.push(if category.is_empty() {
        format!("{}: {message}", status_word(status))
    } else {
        format!("{} [{category}]: {message}", status_word(status))
    });
}

pub(super) fn status_word(status: c_int) -> &'static str {
    match status {
        0 => "OK",
        1 => "Warning",
        2 => "Discard",
        3 => "Error",
        4 => "Fatal",
        5 => "Pending",
        _ => "unknown status",
    }
}
