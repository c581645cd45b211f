//! The extension's run path is `$ORIGIN/../mujoco`: installed from a wheel, `dhrl/` and the
//! `mujoco` package sit side by side in site-packages, so `libmujoco.so.3.17.0` is found in the
//! mujoco wheel wherever the environment lives (and `dhrl/_installed.py` loads that same file
//! before the extension, with a clear error when it is missing or of another version). No
//! folder of the machine that built it is on its library search path. Finding the library to
//! link against (the set-up's folder, or `MUJOCO_DYNAMIC_LINK_DIR`), and the message when it is
//! missing, are the dhrl crate's own build script's.
fn main() {
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rustc-link-arg=-Wl,-rpath,$ORIGIN/../mujoco");
}
