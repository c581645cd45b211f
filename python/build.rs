//! Bakes the folder of the libmujoco.so that `scripts/setup.sh` exposed into the extension's
//! rpath, as the dhrl crate's own build script does for its binaries.
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
    let lib_dir = lib_dir
        .canonicalize()
        .expect("the set-up's library folder exists");
    println!("cargo::rustc-link-arg=-Wl,-rpath,{}", lib_dir.display());
}
