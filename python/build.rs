//! The extension's run path is `$ORIGIN/../mujoco`: installed from a wheel, `dhrl/` and the
//! `mujoco` package sit side by side in site-packages, so `libmujoco.so.3.17.0` is found in the
//! mujoco wheel wherever the environment lives (and `dhrl/_installed.py` loads that same file
//! before the extension, with a clear error when it is missing or of another version). No
//! folder of the machine that built it is on its library search path. Linking needs the library
//! once: from the folder `scripts/setup.sh` exposes (mujoco-rs finds it through
//! `pkgconfig/mujoco.pc`), or, outside the checkout, from `MUJOCO_DYNAMIC_LINK_DIR`.
use std::path::PathBuf;

const LINK_DIR_VAR: &str = "MUJOCO_DYNAMIC_LINK_DIR";

fn main() {
    let root = PathBuf::from(
        std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"),
    );
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-env-changed={LINK_DIR_VAR}");
    let lib_dir = match std::env::var_os(LINK_DIR_VAR) {
        Some(dir) => PathBuf::from(dir),
        None => root.join("../.deps/mujoco/lib"),
    };
    if !lib_dir.join("libmujoco.so").is_file() {
        panic!(
            "\n\nMuJoCo 3.17.0 is not set up ({} has no libmujoco.so).\nIn the repository, run `scripts/setup.sh` once from its root, then build the Python package again; elsewhere, set {LINK_DIR_VAR} to a folder holding libmujoco.so from mujoco 3.17.0.\n\n",
            lib_dir.display()
        );
    }
    println!("cargo::rustc-link-arg=-Wl,-rpath,$ORIGIN/../mujoco");
}
