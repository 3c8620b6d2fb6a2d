//! Who holds an endpoint that a process cannot listen on: the program that
//! listens on its TCP port (or, for a QUIC endpoint, is bound to its UDP port),
//! as Linux's `/proc` says (elsewhere: unknown).

/// The port of an endpoint (`tcp/127.0.0.1:7450`, `quic/[::1]:7450`).
pub(crate) fn port_of(endpoint: &str) -> Option<u16> {
    let address = endpoint.split_once('/').map_or(endpoint, |(_, a)| a);
    let address = address.split('#').next()?;
    address.rsplit_once(':')?.1.parse().ok()
}

/// `pid N: command line` of the process that holds `endpoint`'s port, if the
/// OS says.
pub(crate) fn holder(endpoint: &str) -> Option<String> {
    let port = port_of(endpoint)?;
    let udp = endpoint.starts_with("quic/");
    let inode = socket_inode(port, udp)?;
    let target = format!("socket:[{inode}]");
    for entry in std::fs::read_dir("/proc").ok()?.flatten() {
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(|n| n.parse::<u32>().ok()) else {
            continue;
        };
        let Ok(fds) = std::fs::read_dir(entry.path().join("fd")) else {
            continue;
        };
        let holds = fds.flatten().any(|fd| {
            std::fs::read_link(fd.path()).is_ok_and(|l| l.as_os_str() == target.as_str())
        });
        if holds {
            let cmdline = std::fs::read(entry.path().join("cmdline")).unwrap_or_default();
            let cmdline: Vec<String> = cmdline
                .split(|b| *b == 0)
                .filter(|a| !a.is_empty())
                .map(|a| String::from_utf8_lossy(a).into_owned())
                .collect();
            return Some(format!("pid {pid}: {}", cmdline.join(" ")));
        }
    }
    None
}

/// The inode of the socket that listens on TCP `port`, or (`udp`) is bound to
/// UDP `port` (IPv4 or IPv6).
fn socket_inode(port: u16, udp: bool) -> Option<u64> {
    let port = format!("{port:04X}");
    let tables = if udp {
        ["/proc/net/udp", "/proc/net/udp6"]
    } else {
        ["/proc/net/tcp", "/proc/net/tcp6"]
    };
    // TCP: listening (0A); UDP: any bound socket (07, unconnected, as QUIC's).
    let state = if udp { "07" } else { "0A" };
    for table in tables {
        let Ok(text) = std::fs::read_to_string(table) else {
            continue;
        };
        for line in text.lines().skip(1) {
            let fields: Vec<&str> = line.split_whitespace().collect();
            // sl local_address rem_address st tx:rx tr:tm retrnsmt uid timeout inode
            let (Some(local), Some(st), Some(inode)) =
                (fields.get(1), fields.get(3), fields.get(9))
            else {
                continue;
            };
            if *st == state
                && local.rsplit_once(':').is_some_and(|(_, p)| *p == port)
                && let Ok(inode) = inode.parse::<u64>()
                && inode != 0
            {
                return Some(inode);
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_endpoints_port_is_read_whatever_its_protocol() {
        assert_eq!(port_of("tcp/127.0.0.1:7450"), Some(7450));
        assert_eq!(port_of("quic/[::1]:17800"), Some(17800));
        assert_eq!(port_of("tcp/localhost:80#iface=lo"), Some(80));
        assert_eq!(port_of("tcp/localhost"), None);
    }

    #[test]
    fn the_holder_of_a_listening_port_is_this_process() {
        let Ok(listener) = std::net::TcpListener::bind("127.0.0.1:0") else {
            return;
        };
        let Ok(address) = listener.local_addr() else {
            return;
        };
        let Some(held) = holder(&format!("tcp/127.0.0.1:{}", address.port())) else {
            // No /proc here: nothing to name (the message says "in use" alone).
            assert!(!std::path::Path::new("/proc/net/tcp").exists());
            return;
        };
        assert!(
            held.starts_with(&format!("pid {}:", std::process::id())),
            "{held}"
        );
        let Ok(socket) = std::net::UdpSocket::bind("127.0.0.1:0") else {
            return;
        };
        let Ok(address) = socket.local_addr() else {
            return;
        };
        let held = holder(&format!("quic/127.0.0.1:{}", address.port()));
        assert!(
            held.is_some_and(|h| h.starts_with(&format!("pid {}:", std::process::id()))),
            "a UDP port's holder"
        );
    }
}
