//! SIGINT (Ctrl-C) and SIGTERM (how render farms stop jobs): the first stops a render at the
//! next pixel, which writes the samples finished so far and exits with 128 + the signal's
//! number, as shells report a command the signal ended (130, 143); a second quits at once.

use anyhow::{Context, Result};
use signal_hook::consts::{SIGINT, SIGTERM};
use signal_hook::iterator::Signals;
use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};
use std::sync::Arc;

/// Watches for SIGINT and SIGTERM from [`Interrupt::install`] on.
pub struct Interrupt {
    cancel: Arc<AtomicBool>,
    signal: Arc<AtomicI32>,
}

/// What a command returns when a signal stopped it after it wrote what it had: `main` exits
/// with this status and prints nothing more.
#[derive(Debug, thiserror::Error)]
#[error("interrupted by signal {}", .exit_code - 128)]
pub struct Interrupted {
    pub exit_code: i32,
}

impl Interrupt {
    pub fn install() -> Result<Self> {
        let cancel = Arc::new(AtomicBool::new(false));
        let signal = Arc::new(AtomicI32::new(0));
        let mut signals =
            Signals::new([SIGINT, SIGTERM]).context("installing the SIGINT/SIGTERM handler")?;
        let (flag, received) = (Arc::clone(&cancel), Arc::clone(&signal));
        std::thread::spawn(move || {
            for sig in signals.forever() {
                if flag.swap(true, Ordering::SeqCst) {
                    eprintln!("interrupted again: quitting without writing");
                    std::process::exit(128 + sig);
                }
                received.store(sig, Ordering::SeqCst);
                let name = if sig == SIGTERM {
                    "SIGTERM"
                } else {
                    "interrupt"
                };
                eprintln!(
                    "{name}: stopping and writing the samples finished so far (a second signal \
                     quits at once)"
                );
            }
        });
        Ok(Interrupt { cancel, signal })
    }

    /// Set once a signal arrived: the render polls it.
    pub fn cancel_flag(&self) -> &Arc<AtomicBool> {
        &self.cancel
    }

    /// The error to return once the stopped render is written.
    pub fn interrupted(&self) -> Interrupted {
        let sig = match self.signal.load(Ordering::SeqCst) {
            0 => SIGINT,
            s => s,
        };
        Interrupted {
            exit_code: 128 + sig,
        }
    }
}
