//! Flush-to-zero and denormals-are-zero on the threads that do dhrl's math.
//!
//! Adam's moment estimates decay into the subnormal range (below ~1.2e-38 in f32), and Intel
//! cores take a slow microcode assist for every subnormal operand or result: measured with
//! `perf`, 20–26% of a SAC run's time on a Xeon sat in Adam's elementwise kernel (AMD cores
//! barely notice). With the modes on, a subnormal operand reads as 0 and a subnormal result is
//! written as 0, so those operations run at full speed; values that small change no update.
//!
//! The mode is a per-thread register (x86_64: MXCSR bits 15 FTZ and 6 DAZ; aarch64: FPCR bit 24
//! FZ; a no-op elsewhere). dhrl turns it on for the threads it owns: the CLI's main thread, every
//! rayon pool it builds ([`thread_pool`]), and, around a call only, a caller's thread
//! ([`FlushGuard`], which restores the caller's mode, so a Python process's own numpy math is
//! never changed). Physics threads get it too: one copy steps on the calling thread and many on
//! the pool, and a run must not depend on the thread count. Gymnasium parity (bit-identical
//! traces) holds with it on. `DHRL_FLUSH_SUBNORMALS=0` in the environment turns all of this off.
use std::sync::LazyLock;

/// Whether dhrl turns the mode on (`DHRL_FLUSH_SUBNORMALS=0` says no; anything else, or unset,
/// yes). Read once per process.
pub fn enabled() -> bool {
    static ENABLED: LazyLock<bool> =
        LazyLock::new(|| std::env::var("DHRL_FLUSH_SUBNORMALS").map_or(true, |v| v.trim() != "0"));
    *ENABLED
}

/// Whether this thread flushes subnormals now (read from the register).
pub fn flushing() -> bool {
    arch::read() & arch::FLUSH_BITS == arch::FLUSH_BITS && arch::FLUSH_BITS != 0
}

/// Turns the mode on for this thread if [`enabled`]: for threads dhrl owns for their whole life.
pub fn apply_to_this_thread() {
    if enabled() {
        arch::write(arch::read() | arch::FLUSH_BITS);
    }
}

/// The mode set (if [`enabled`]) for as long as it lives, the thread's previous mode restored
/// when it drops: for a thread that is not dhrl's, such as a Python caller's.
#[must_use = "the mode is restored when the guard drops"]
pub struct FlushGuard {
    saved: u32,
}

impl FlushGuard {
    pub fn new() -> FlushGuard {
        let saved = arch::read();
        apply_to_this_thread();
        FlushGuard { saved }
    }
}

impl Default for FlushGuard {
    fn default() -> Self {
        FlushGuard::new()
    }
}

impl Drop for FlushGuard {
    fn drop(&mut self) {
        arch::write(self.saved);
    }
}

/// A rayon pool of `threads` threads named `name-i`, each with the mode on from its start.
pub fn thread_pool(
    threads: usize,
    name: &'static str,
) -> Result<rayon::ThreadPool, rayon::ThreadPoolBuildError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(move |i| format!("{name}-{i}"))
        .start_handler(|_| apply_to_this_thread())
        .build()
}

/// Whether a product whose exact value is subnormal comes out as zero on this thread: the
/// observable effect, for tests and `dhrl bench`.
pub fn subnormal_product_is_zero() -> bool {
    let tiny = std::hint::black_box(1e-30f32) * std::hint::black_box(1e-10f32);
    tiny == 0.0
}

#[cfg(target_arch = "x86_64")]
mod arch {
    use std::arch::asm;
    /// MXCSR's flush-to-zero (bit 15) and denormals-are-zero (bit 6).
    pub const FLUSH_BITS: u32 = (1 << 15) | (1 << 6);

    pub fn read() -> u32 {
        let mut csr: u32 = 0;
        // SAFETY: stmxcsr stores the 32-bit MXCSR register into `csr`.
        unsafe { asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack, preserves_flags)) };
        csr
    }

    pub fn write(csr: u32) {
        // SAFETY: ldmxcsr loads a value read from MXCSR with only the FTZ/DAZ bits changed,
        // so no reserved bit is set.
        unsafe { asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack, preserves_flags)) };
    }
}

#[cfg(target_arch = "aarch64")]
mod arch {
    use std::arch::asm;
    /// FPCR's flush-to-zero (FZ, bit 24); it covers inputs and outputs.
    pub const FLUSH_BITS: u32 = 1 << 24;

    pub fn read() -> u32 {
        let fpcr: u64;
        // SAFETY: reading FPCR has no side effects.
        unsafe { asm!("mrs {}, fpcr", out(reg) fpcr, options(nomem, nostack, preserves_flags)) };
        fpcr as u32
    }

    pub fn write(fpcr: u32) {
        // SAFETY: writes back a value read from FPCR with only FZ changed.
        unsafe {
            asm!("msr fpcr, {}", in(reg) fpcr as u64, options(nomem, nostack, preserves_flags))
        };
    }
}

#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
mod arch {
    pub const FLUSH_BITS: u32 = 0;
    pub fn read() -> u32 {
        0
    }
    pub fn write(_: u32) {}
}
