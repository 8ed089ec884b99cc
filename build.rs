//! Generates the ROS1 message and service types (the `ros1` feature) from the interface
//! definitions kept in the repository, so their md5sums are what any ROS client computes
//! from the same files.

fn main() {
    #[cfg(feature = "ros1")]
    ros1_interfaces();
}

#[cfg(feature = "ros1")]
fn ros1_interfaces() {
    use std::path::PathBuf;

    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("set by cargo"));
    let interfaces = root.join("crates/core/src/api/ros1/interfaces");
    let (source, files) =
        roslibrust_codegen::find_and_generate_ros_messages_without_ros_package_path(vec![
            interfaces.clone(),
        ])
        .unwrap_or_else(|e| panic!("cannot generate the ROS1 types from {interfaces:?}: {e}"));
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("set by cargo"));
    std::fs::write(out.join("ros1_interfaces.rs"), source.to_string())
        .expect("OUT_DIR is writable");
    println!("cargo:rerun-if-changed={}", interfaces.display());
    for file in files {
        println!("cargo:rerun-if-changed={}", file.display());
    }
}
