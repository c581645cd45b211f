//! Finds MuJoCo 3.17.0 and bakes its folder into the rpath of every binary, test and bench, so
//! nothing has to be on `LD_LIBRARY_PATH`. In the repository that is the folder
//! `scripts/setup.sh` exposes (mujoco-rs links it through `pkgconfig/mujoco.pc`); a build of the
//! packaged crate elsewhere names it with `MUJOCO_DYNAMIC_LINK_DIR`, which mujoco-rs links from
//! too. Without either the build stops here, before any linker runs, with one message naming
//! what to do.
use std::path::PathBuf;

const LINK_DIR_VAR: &str = "MUJOCO_DYNAMIC_LINK_DIR";

fn main() {
    let root = PathBuf::from(
        std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"),
    );
    let setup_dir = root.join(".deps/mujoco/lib");
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-env-changed={LINK_DIR_VAR}");
    println!(
        "cargo::rerun-if-changed={}",
        setup_dir.join("libmujoco.so").display()
    );
    let lib_dir = match std::env::var_os(LINK_DIR_VAR) {
        Some(dir) => PathBuf::from(dir),
        None => setup_dir,
    };
    if !lib_dir.join("libmujoco.so").is_file() {
        panic!(
            "\n\nMuJoCo 3.17.0 is not set up ({} has no libmujoco.so).\nIn the repository, run `scripts/setup.sh` once (it fetches the mujoco and gymnasium wheels into .deps/), then build again; elsewhere, set {LINK_DIR_VAR} to a folder holding libmujoco.so from mujoco 3.17.0.\n\n",
            lib_dir.display()
        );
    }
    println!("cargo::rustc-link-arg=-Wl,-rpath,{}", lib_dir.display());
}
