//! What the automatic design's tests share.

use std::sync::Mutex;

use twostage::Progress;

/// The notes a run gives, kept to be read.
#[derive(Default)]
pub struct Notes(pub Mutex<Vec<String>>);

impl Progress for Notes {
    fn note(&self, message: &str) {
        // A poisoned lock only follows another test's panic.
        if let Ok(mut notes) = self.0.lock() {
            notes.push(message.to_string());
        }
    }
}
