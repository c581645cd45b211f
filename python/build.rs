//! The extension's run path is `$ORIGIN/../mujoco`: installed from a wheel, `dhrl/` and the
//! `mujoco` package sit side by side in site-packages, so `libmujoco.so.3.17.0` is found in the
//! mujoco wheel wherever the environment lives (and `dhrl/_installed.py` loads that same file
//! before the extension, with a clear error when it is missing or of another version). Nothing
//! of the checkout that built it is baked in. Linking needs the library once, from the folder
//! `scripts/setup.sh` exposes (mujoco-rs finds it through `pkgconfig/mujoco.pc`).
use std::path::PathBuf;

fn main() {
    let root = PathBuf::from(
        std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"),
    );
    let lib_dir = root.join("../.deps/mujoco/lib");
    println!("cargo::rerun-if-changed=build.rs");
    if !lib_dir.join("libmujoco.so").is_file() {
        panic!(
            "\n\nMuJoCo 3.17.0 is not set up ({} has no libmujoco.so).\nRun `scripts/setup.sh` once from the repository root, then build the Python package again.\n\n",
            lib_dir.display()
        );
    }
    println!("cargo::rustc-link-arg=-Wl,-rpath,$ORIGIN/../mujoco");
}
