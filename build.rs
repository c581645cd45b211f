//! Checks that `scripts/setup.sh` has exposed MuJoCo 3.17.0 (mujoco-rs links it through
//! `pkgconfig/mujoco.pc`) and bakes its folder into the rpath of every binary, test and bench,
//! so nothing has to be on `LD_LIBRARY_PATH`. Without the set-up the build stops here, before
//! any linker runs, with one message naming the command to run.
use std::path::PathBuf;

fn main() {
    let root = PathBuf::from(
        std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"),
    );
    let lib_dir = root.join(".deps/mujoco/lib");
    println!("cargo::rerun-if-changed=build.rs");
    println!(
        "cargo::rerun-if-changed={}",
        lib_dir.join("libmujoco.so").display()
    );
    if !lib_dir.join("libmujoco.so").is_file() {
        panic!(
            "\n\nMuJoCo 3.17.0 is not set up ({} has no libmujoco.so).\nRun `scripts/setup.sh` once (it fetches the mujoco and gymnasium wheels into .deps/), then build again.\n\n",
            lib_dir.display()
        );
    }
    println!("cargo::rustc-link-arg=-Wl,-rpath,{}", lib_dir.display());
}
