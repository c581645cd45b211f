//! Finds the MuJoCo library that `scripts/setup.sh` exposes and bakes its folder into the rpath
//! of every binary, test and bench, so nothing has to be on `LD_LIBRARY_PATH`.
use std::path::PathBuf;

fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    println!("cargo::rerun-if-changed=build.rs");
    let Some(lib_dir) = std::env::var_os("MUJOCO_DYNAMIC_LINK_DIR").map(PathBuf::from) else {
        panic!(
            "MUJOCO_DYNAMIC_LINK_DIR is not set. Build from the repository root (its .cargo/config.toml sets it) \
             after running `scripts/setup.sh`."
        );
    };
    if !lib_dir.join("libmujoco.so").is_file() {
        panic!(
            "MuJoCo 3.17.0 is not set up: {} has no libmujoco.so. Run `scripts/setup.sh` first.",
            lib_dir.display()
        );
    }
    println!("cargo::rustc-link-arg=-Wl,-rpath,{}", lib_dir.display());
}
