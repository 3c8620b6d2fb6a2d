//! SIGINT, SIGTERM and SIGHUP as flags that every run loop watches: a run stops
//! at its next look (within milliseconds), finishes its recording and prints its
//! summary. A second Ctrl-C ends the program at once (exit 130).

use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};

/// The program's stop signals.
#[derive(Debug)]
pub struct Signals {
    int: Arc<AtomicBool>,
    term: Arc<AtomicBool>,
    hup: Arc<AtomicBool>,
    /// Set by any of them.
    any: Arc<AtomicBool>,
    /// Why the handlers could not be installed, if they could not.
    refused: Option<String>,
}

static SIGNALS: OnceLock<Signals> = OnceLock::new();

impl Signals {
    /// The program's signals, their handlers installed on the first call.
    pub fn get() -> &'static Signals {
        SIGNALS.get_or_init(|| {
            use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
            use signal_hook::flag;
            let s = Signals {
                int: Arc::new(AtomicBool::new(false)),
                term: Arc::new(AtomicBool::new(false)),
                hup: Arc::new(AtomicBool::new(false)),
                any: Arc::new(AtomicBool::new(false)),
                refused: None,
            };
            // A second SIGINT while the first is being handled ends the
            // program (registered first: it tests the flag before it is set).
            let installed = flag::register_conditional_shutdown(SIGINT, 130, s.int.clone())
                .and_then(|_| flag::register(SIGINT, s.int.clone()))
                .and_then(|_| flag::register(SIGTERM, s.term.clone()))
                .and_then(|_| flag::register(SIGHUP, s.hup.clone()))
                .and_then(|_| {
                    for sig in [SIGINT, SIGTERM, SIGHUP] {
                        flag::register(sig, s.any.clone())?;
                    }
                    Ok(())
                });
            Signals {
                refused: installed.err().map(|e| e.to_string()),
                ..s
            }
        })
    }

    /// The program's signals if [`Signals::get`] installed their handlers (a
    /// library's loop watches them then, and installs nothing itself).
    pub fn installed() -> Option<&'static Signals> {
        SIGNALS.get()
    }

    /// The signal that asked the program to stop, if one did.
    pub fn received(&self) -> Option<&'static str> {
        if self.int.load(Ordering::Relaxed) {
            Some("SIGINT")
        } else if self.term.load(Ordering::Relaxed) {
            Some("SIGTERM")
        } else if self.hup.load(Ordering::Relaxed) {
            Some("SIGHUP")
        } else {
            None
        }
    }

    /// Whether a stop signal came.
    pub fn stopping(&self) -> bool {
        self.received().is_some()
    }

    /// A flag set as soon as a stop signal comes (for waits that take one).
    pub fn flag(&self) -> Arc<AtomicBool> {
        self.any.clone()
    }

    /// Why the handlers could not be installed (the program then ends at
    /// once on a signal, without its summary).
    pub fn refused(&self) -> Option<&str> {
        self.refused.as_deref()
    }
}
