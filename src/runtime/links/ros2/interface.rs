//! Where DDS runs: the addresses of `[ros2]`'s discovery range and interface, its domain and
//! the middleware framing of the action's services (from the configuration, else ROS 2's
//! environment: `ROS_DOMAIN_ID`, `RMW_IMPLEMENTATION`), checked where the configuration is
//! loaded (a wrong one is a configuration error, exit 78, with the fix).

use std::net::{IpAddr, Ipv4Addr};
use std::path::Path;

use crate::config::ConfigError;
use crate::config::ros2::{Discovery, Middleware, Ros2Config};

/// Where and how the node joins DDS.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Joining {
    /// The domain.
    pub domain: u16,
    /// The addresses DDS uses (`None`: every interface).
    pub networks: Option<Vec<IpAddr>>,
    /// How the action's requests are framed.
    pub middleware: Middleware,
}

/// Where and how the node of `config` joins DDS, or why it cannot. `file` names the
/// configuration in the error.
pub fn resolve(config: &Ros2Config, file: &Path) -> Result<Joining, ConfigError> {
    let env = std::env::var("ROS_DOMAIN_ID").ok();
    let domain = config.domain(env.as_deref()).map_err(|problem| {
        ConfigError::invalid(
            file,
            "ros2.domain_id",
            problem,
            "set ROS_DOMAIN_ID to a number from 0 to 232, unset it, or set ros2.domain_id",
        )
    })?;
    let networks = match (&config.interface, config.discovery) {
        (Some(name), _) => Some(vec![IpAddr::V4(ipv4_of(name, file)?)]),
        (None, Discovery::Localhost) => Some(vec![IpAddr::V4(Ipv4Addr::LOCALHOST)]),
        (None, Discovery::Subnet) => None,
    };
    let rmw = std::env::var("RMW_IMPLEMENTATION").ok();
    Ok(Joining {
        domain,
        networks,
        middleware: config.middleware(rmw.as_deref()),
    })
}

/// The IPv4 address of interface `name`.
fn ipv4_of(name: &str, file: &Path) -> Result<Ipv4Addr, ConfigError> {
    let interfaces = ipv4_interfaces();
    if let Some((_, address)) = interfaces.iter().find(|(n, _)| n == name) {
        return Ok(*address);
    }
    let known: Vec<&str> = interfaces.iter().map(|(n, _)| n.as_str()).collect();
    Err(ConfigError::invalid(
        file,
        "ros2.interface",
        format!("there is no interface {name:?} with an IPv4 address on this machine"),
        &format!(
            "name one of {} (as `ip -4 addr` lists them), or leave ros2.interface out",
            if known.is_empty() {
                "the machine's interfaces".to_owned()
            } else {
                known.join(", ")
            }
        ),
    ))
}

/// The machine's interfaces that have an IPv4 address, with it (the first of each).
fn ipv4_interfaces() -> Vec<(String, Ipv4Addr)> {
    let mut found: Vec<(String, Ipv4Addr)> = Vec::new();
    let mut list: *mut libc::ifaddrs = std::ptr::null_mut();
    // SAFETY: getifaddrs fills `list` with a linked list freed by freeifaddrs below; each
    // node's name is a NUL-terminated string and its address, when not null, a sockaddr of
    // the family it states.
    unsafe {
        if libc::getifaddrs(&mut list) != 0 {
            return found;
        }
        let mut node = list;
        while !node.is_null() {
            let entry = &*node;
            node = entry.ifa_next;
            if entry.ifa_addr.is_null()
                || i32::from((*entry.ifa_addr).sa_family) != libc::AF_INET
                || entry.ifa_name.is_null()
            {
                continue;
            }
            let address = &*(entry.ifa_addr as *const libc::sockaddr_in);
            let ip = Ipv4Addr::from(u32::from_be(address.sin_addr.s_addr));
            let name = std::ffi::CStr::from_ptr(entry.ifa_name)
                .to_string_lossy()
                .into_owned();
            if !found.iter().any(|(n, _)| *n == name) {
                found.push((name, ip));
            }
        }
        libc::freeifaddrs(list);
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_is_found_and_a_missing_interface_is_refused_with_the_fix() {
        let file = Path::new("v.toml");
        let lo = Ros2Config {
            interface: Some("lo".into()),
            ..Default::default()
        };
        let joining = resolve(&lo, file).unwrap();
        assert_eq!(
            joining.networks,
            Some(vec![IpAddr::V4(Ipv4Addr::LOCALHOST)])
        );
        let missing = Ros2Config {
            interface: Some("nosuch0".into()),
            ..Default::default()
        };
        let e = resolve(&missing, file).unwrap_err().to_string();
        assert!(
            e.contains("ros2.interface") && e.contains("nosuch0") && e.contains("lo"),
            "{e}"
        );
        let subnet = Ros2Config {
            discovery: Discovery::Subnet,
            domain_id: Some(3),
            ..Default::default()
        };
        let joining = resolve(&subnet, file).unwrap();
        assert_eq!((joining.domain, joining.networks), (3, None));
    }
}
