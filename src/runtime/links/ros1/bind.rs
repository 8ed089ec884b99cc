//! The node's ports kept to the address it advertises. roslibrust 0.26 listens on 0.0.0.0
//! for every one of them (XML-RPC, each topic's and each service's TCPROS; its
//! `node::determine_addr` hard-codes it, as roscpp does) and has no setting for it. chassisd
//! cannot bind them itself, so each gets a socket filter (classic BPF, which every
//! connection the listener accepts inherits) that drops the packets addressed to any other
//! address: seen from outside, the port exists on the advertised address only, as if
//! bound there (a connection elsewhere gets no answer rather than a reset).
//!
//! Which address: the one roslibrust advertises, when `ROS_IP` or `ROS_HOSTNAME` names it;
//! with neither, loopback when the master is on loopback and the host name roslibrust
//! advertises resolves to loopback only. Otherwise the ports stay on every interface, as
//! ROS's own nodes have them, and the log says so.

use std::net::{IpAddr, Ipv4Addr};
use std::os::fd::{BorrowedFd, RawFd};

use socket2::{SockFilter, SockRef};

/// The destinations the node's ports take.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Allowed {
    /// These addresses only.
    Exactly(Vec<Ipv4Addr>),
    /// 127.0.0.0/8.
    Loopback,
}

/// The most addresses a filter names (a host name's records; jumps are 8-bit).
const MOST_ADDRESSES: usize = 16;

/// The destinations for a node advertised as `host` (its XML-RPC URI's host), whose master
/// is on loopback or not; `None` when its ports stay on every interface.
pub async fn allowed(host: &str, master_on_loopback: bool) -> Option<Allowed> {
    let named = std::env::var_os("ROS_IP").is_some() || std::env::var_os("ROS_HOSTNAME").is_some();
    let addresses = resolve(host).await;
    if addresses.is_empty() || addresses.len() > MOST_ADDRESSES {
        return None;
    }
    if named {
        Some(Allowed::Exactly(addresses))
    } else if master_on_loopback && addresses.iter().all(Ipv4Addr::is_loopback) {
        Some(Allowed::Loopback)
    } else {
        None
    }
}

/// `host`'s IPv4 addresses (roslibrust listens on IPv4 only).
async fn resolve(host: &str) -> Vec<Ipv4Addr> {
    if let Ok(ip) = host.parse::<Ipv4Addr>() {
        return vec![ip];
    }
    let Ok(found) = tokio::net::lookup_host((host, 0)).await else {
        return Vec::new();
    };
    let mut addresses: Vec<Ipv4Addr> = found
        .filter_map(|a| match a.ip() {
            IpAddr::V4(ip) => Some(ip),
            IpAddr::V6(_) => None,
        })
        .collect();
    addresses.sort_unstable();
    addresses.dedup();
    addresses
}

/// Whether the master's URI (`http://host:port`) names a loopback host.
pub fn master_on_loopback(uri: &str) -> bool {
    let rest = uri
        .strip_prefix("http://")
        .or_else(|| uri.strip_prefix("https://"))
        .unwrap_or(uri);
    let host = rest.split([':', '/']).next().unwrap_or("");
    host.eq_ignore_ascii_case("localhost")
        || host.parse::<Ipv4Addr>().is_ok_and(|ip| ip.is_loopback())
}

/// The filter: accept a packet whose IPv4 destination is allowed, drop the rest.
fn program(allowed: &Allowed) -> Vec<SockFilter> {
    // Classic BPF opcodes (linux/filter.h).
    const LD_W_ABS: u16 = 0x20; // BPF_LD | BPF_W | BPF_ABS
    const ALU_AND_K: u16 = 0x54; // BPF_ALU | BPF_AND | BPF_K
    const JMP_JEQ_K: u16 = 0x15; // BPF_JMP | BPF_JEQ | BPF_K
    const RET_K: u16 = 0x06; // BPF_RET | BPF_K
    // The IPv4 header's destination, from the network header (SKF_NET_OFF): the packet's
    // data starts at the TCP header when a TCP socket's filter runs.
    const DESTINATION: u32 = (-0x10_0000_i32 + 16) as u32;
    let mut p = vec![SockFilter::new(LD_W_ABS, 0, 0, DESTINATION)];
    match allowed {
        Allowed::Loopback => {
            p.push(SockFilter::new(ALU_AND_K, 0, 0, 0xff00_0000));
            p.push(SockFilter::new(JMP_JEQ_K, 1, 0, 0x7f00_0000));
        }
        Allowed::Exactly(addresses) => {
            let n = addresses.len().min(MOST_ADDRESSES);
            for (i, ip) in addresses.iter().take(n).enumerate() {
                // To the accepting return after the dropping one.
                let to_accept = u8::try_from(n - i).unwrap_or(u8::MAX);
                p.push(SockFilter::new(JMP_JEQ_K, to_accept, 0, u32::from(*ip)));
            }
        }
    }
    p.push(SockFilter::new(RET_K, 0, 0, 0));
    p.push(SockFilter::new(RET_K, 0, 0, u32::MAX));
    p
}

/// Puts the filter of `allowed` on every IPv4 socket of the process listening on 0.0.0.0
/// but chassisd's own servers' (`runtime::listeners`): roslibrust's. Returns how many.
pub fn restrict(allowed: &Allowed) -> std::io::Result<usize> {
    let program = program(allowed);
    let mut filtered = 0;
    for fd in std::fs::read_dir("/proc/self/fd")? {
        let Some(fd) = fd
            .ok()
            .and_then(|e| e.file_name().to_str().and_then(|n| n.parse::<RawFd>().ok()))
        else {
            continue;
        };
        // SAFETY: the descriptor is only queried and given a filter, never closed or read.
        // Another thread may close it meanwhile; its number, taken again, would get the
        // filter only if it is again a listener on 0.0.0.0 that is not chassisd's.
        let borrowed = unsafe { BorrowedFd::borrow_raw(fd) };
        let socket = SockRef::from(&borrowed);
        if !socket.is_listener().unwrap_or(false) {
            continue;
        }
        let Some(address) = socket.local_addr().ok().and_then(|a| a.as_socket_ipv4()) else {
            continue;
        };
        if !address.ip().is_unspecified() || crate::runtime::listeners::is_own(address.port()) {
            continue;
        }
        socket.attach_filter(&program)?;
        filtered += 1;
    }
    Ok(filtered)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masters_on_loopback_are_told_apart() {
        assert!(master_on_loopback("http://127.0.0.1:11311"));
        assert!(master_on_loopback("http://localhost:11311/"));
        assert!(!master_on_loopback("http://10.0.0.5:11311"));
        assert!(!master_on_loopback("http://robot.local:11311"));
    }

    #[test]
    fn a_filtered_listener_takes_connections_to_its_address_only() {
        use std::net::{SocketAddr, TcpListener, TcpStream};
        use std::time::Duration;
        let listener = TcpListener::bind("0.0.0.0:0").expect("bind");
        let port = listener.local_addr().unwrap().port();
        let exactly = program(&Allowed::Exactly(vec![Ipv4Addr::LOCALHOST]));
        SockRef::from(&listener).attach_filter(&exactly).unwrap();
        let to = |ip: [u8; 4]| {
            TcpStream::connect_timeout(&SocketAddr::from((ip, port)), Duration::from_millis(500))
        };
        assert!(to([127, 0, 0, 1]).is_ok());
        assert!(to([127, 0, 0, 2]).is_err(), "dropped: no answer");
        let listener = TcpListener::bind("0.0.0.0:0").expect("bind");
        let port = listener.local_addr().unwrap().port();
        SockRef::from(&listener)
            .attach_filter(&program(&Allowed::Loopback))
            .unwrap();
        let connect = TcpStream::connect_timeout(
            &SocketAddr::from(([127, 0, 0, 9], port)),
            Duration::from_millis(500),
        );
        assert!(connect.is_ok());
    }
}
