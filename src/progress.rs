//! The progress of a long loop (training, a sweep), for whoever watches it. With the `cli`
//! feature it is an indicatif bar on stderr (steps, rate, ETA and a message); a library build
//! without it draws nothing and prints each new message as a line on stderr instead.

/// A progress display over `len` steps; hidden ones show nothing at all.
pub struct Progress {
    #[cfg(feature = "cli")]
    bar: indicatif::ProgressBar,
    #[cfg(not(feature = "cli"))]
    visible: bool,
    #[cfg(not(feature = "cli"))]
    position: std::sync::atomic::AtomicU64,
    #[cfg(not(feature = "cli"))]
    len: u64,
    /// The last message printed: a repeated one is not printed again.
    #[cfg(not(feature = "cli"))]
    message: std::sync::Mutex<String>,
}

impl Progress {
    /// A bar over `len` steps, drawn with `template` (indicatif's syntax) when `visible`.
    pub fn new(len: u64, template: &str, visible: bool) -> Self {
        #[cfg(feature = "cli")]
        {
            let bar = if visible {
                indicatif::ProgressBar::new(len)
            } else {
                indicatif::ProgressBar::hidden()
            };
            bar.set_style(
                indicatif::ProgressStyle::with_template(template).expect("a valid template"),
            );
            Self { bar }
        }
        #[cfg(not(feature = "cli"))]
        {
            let _ = template;
            Self {
                visible,
                position: std::sync::atomic::AtomicU64::new(0),
                len,
                message: std::sync::Mutex::new(String::new()),
            }
        }
    }

    /// Steps done so far.
    pub fn set_position(&self, position: u64) {
        #[cfg(feature = "cli")]
        self.bar.set_position(position);
        #[cfg(not(feature = "cli"))]
        self.position
            .store(position, std::sync::atomic::Ordering::Relaxed);
    }

    /// Starts the rate and ETA estimate afresh (after `set_position` of a resumed loop).
    pub fn reset_eta(&self) {
        #[cfg(feature = "cli")]
        self.bar.reset_eta();
    }

    /// The message beside the bar (or, without the `cli` feature, a line with the position when
    /// the message is new).
    pub fn set_message(&self, message: String) {
        #[cfg(feature = "cli")]
        self.bar.set_message(message);
        #[cfg(not(feature = "cli"))]
        {
            let mut last = self.message.lock().unwrap_or_else(|e| e.into_inner());
            if self.visible && *last != message {
                eprintln!(
                    "{}/{} steps  {message}",
                    self.position.load(std::sync::atomic::Ordering::Relaxed),
                    self.len
                );
            }
            *last = message;
        }
    }

    /// Runs `f` (which prints) with the bar out of the way.
    pub fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        #[cfg(feature = "cli")]
        return self.bar.suspend(f);
        #[cfg(not(feature = "cli"))]
        f()
    }

    /// A line above the bar (on stderr).
    pub fn println(&self, line: String) {
        self.suspend(|| eprintln!("{line}"));
    }

    /// Leaves the bar where it stopped.
    pub fn abandon(&self) {
        #[cfg(feature = "cli")]
        self.bar.abandon();
    }

    /// Completes the bar.
    pub fn finish(&self) {
        #[cfg(feature = "cli")]
        self.bar.finish();
    }
}
