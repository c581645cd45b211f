//! Bakes the folder of the MuJoCo library that `scripts/setup.sh` exposes (`.cargo/config.toml`
//! sets MUJOCO_DYNAMIC_LINK_DIR to it) into the rpath of every binary, test and bench, so
//! nothing has to be on `LD_LIBRARY_PATH`. Without the set-up, mujoco-rs's own build script
//! stops first, naming the missing `.deps/mujoco/lib/libmujoco.so`.
fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    println!("cargo::rerun-if-changed=build.rs");
    match std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        Ok(lib_dir) => println!("cargo::rustc-link-arg=-Wl,-rpath,{lib_dir}"),
        Err(_) => println!(
            "cargo::warning=MUJOCO_DYNAMIC_LINK_DIR is not set: build from the repository root after `scripts/setup.sh`"
        ),
    }
}
