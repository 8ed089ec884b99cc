//! Generates the ROS1 message and service types (the `ros1` feature) and the ROS 2 message
//! types (the `ros2` feature) from the interface definitions kept in the repository, so their
//! md5sums and RIHS01 type hashes are what any ROS client computes from the same files.

fn main() {
    #[cfg(feature = "ros1")]
    ros1_interfaces();
    #[cfg(feature = "ros2")]
    ros2_interfaces();
}

#[cfg(feature = "ros1")]
fn ros1_interfaces() {
    let source = generate("crates/core/src/api/ros1/interfaces", "ROS1");
    write("ros1_interfaces.rs", &source);
}

/// roslibrust_codegen reads a package as ROS 2's when its package.xml names ament_cmake as
/// its build tool; builtin_interfaces (Time, Duration) and service_msgs come with it.
#[cfg(feature = "ros2")]
fn ros2_interfaces() {
    let mut source = generate("crates/core/src/api/ros2/interfaces", "ROS 2");
    for (type_name, generated, ros2) in ROS2_HASH_FIXES {
        let generated = hash_tokens(generated);
        assert_eq!(
            source.matches(&generated).count(),
            1,
            "roslibrust_codegen's RIHS01 hash of {type_name} changed: check it and ROS2_HASH_FIXES"
        );
        source = source.replacen(&generated, &hash_tokens(ros2), 1);
    }
    write("ros2_interfaces.rs", &source);
}

/// RIHS01 type hashes roslibrust_codegen 0.26 gets wrong, replaced by ROS 2's: it hashes a
/// `byte` field as a nested type (its table knows IDL's `octet`, not the .msg's `byte`), so
/// DiagnosticStatus (`byte level`) and the DiagnosticArray holding it differ from what ROS 2
/// Jazzy (and rosbags) compute. The type, the hash generated, ROS 2's. When a roslibrust
/// release fixes it, the generated hash is no longer found and the build stops here: remove
/// the entry.
#[cfg(feature = "ros2")]
const ROS2_HASH_FIXES: &[(&str, &str, &str)] = &[
    (
        "diagnostic_msgs/DiagnosticStatus",
        "405fee4fdad6cce5341d944ac782eb849e414027bbe672cafff502302f03802b",
        "b0e3e692ea2d54a8af2f4ef1930e81556a2db55216b771f8a7d2724ed47bf0e4",
    ),
    (
        "diagnostic_msgs/DiagnosticArray",
        "f9eef075d53ad59209151268b37ab3191f7a854417107bb76ff9d56c4bfee92c",
        "5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
    ),
];

/// The generated source's spelling of a 32-byte hash given in hex (`0x40 , 0x5f , …`).
#[cfg(feature = "ros2")]
fn hash_tokens(hex: &str) -> String {
    (0..hex.len())
        .step_by(2)
        .map(|i| format!("0x{}", &hex[i..i + 2]))
        .collect::<Vec<_>>()
        .join(" , ")
}

/// The types of the interface definitions under `folder` (its packages' .msg and .srv), as
/// Rust source; cargo runs this again when one of them changes.
#[cfg(any(feature = "ros1", feature = "ros2"))]
fn generate(folder: &str, which: &str) -> String {
    let root = std::path::PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("set by cargo"));
    let interfaces = root.join(folder);
    let (source, files) =
        roslibrust_codegen::find_and_generate_ros_messages_without_ros_package_path(vec![
            interfaces.clone(),
        ])
        .unwrap_or_else(|e| panic!("cannot generate the {which} types from {interfaces:?}: {e}"));
    println!("cargo:rerun-if-changed={}", interfaces.display());
    for file in &files {
        println!("cargo:rerun-if-changed={}", file.display());
    }
    let mut source = source.to_string();
    if !files
        .iter()
        .any(|f| f.extension().is_some_and(|e| e == "srv"))
    {
        // Without a service the generated `use ::roslibrust::{.., RosServiceType as _}` is an
        // unused import (the ROS 2 set has none: the action's services are ros2-client's).
        source = source.replacen("RosServiceType as _", "", 1);
    }
    source
}

#[cfg(any(feature = "ros1", feature = "ros2"))]
fn write(file: &str, source: &str) {
    let out = std::path::PathBuf::from(std::env::var("OUT_DIR").expect("set by cargo"));
    std::fs::write(out.join(file), source).expect("OUT_DIR is writable");
}
