//! Four hosts on one machine: network namespaces joined by a bridge (root and
//! `ip` needed).

use std::process::Command;

/// Four network namespaces ("hosts") with addresses 10.57.0.1-4/24 on `eth0`,
/// joined by veth pairs to a bridge in a fifth; deleted when dropped (every
/// veth and the bridge go with them).
pub(crate) struct Hosts {
    names: Vec<String>,
}

pub(crate) const HOSTS: usize = 4;

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "`ip {}`: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

impl Hosts {
    fn prefix(pid: u32) -> String {
        format!("zscale{pid}-")
    }

    pub(crate) fn host(&self, h: usize) -> &str {
        &self.names[h]
    }

    pub(crate) fn address(h: usize) -> String {
        format!("10.57.0.{}", h + 1)
    }

    pub(crate) fn make() -> Result<Hosts, String> {
        Self::remove_stale();
        let p = Self::prefix(std::process::id());
        let mut names: Vec<String> = (0..HOSTS).map(|h| format!("{p}h{h}")).collect();
        let switch = format!("{p}sw");
        names.push(switch.clone());
        // From here on, dropping `hosts` deletes what was made.
        let hosts = Hosts { names };
        for ns in &hosts.names {
            ip(&["netns", "add", ns])?;
        }
        let sw = switch.as_str();
        ip(&["-n", sw, "link", "add", "br0", "type", "bridge"])?;
        ip(&["-n", sw, "link", "set", "br0", "up"])?;
        for h in 0..HOSTS {
            let (ns, port) = (hosts.host(h), format!("p{h}"));
            ip(&[
                "-n", sw, "link", "add", &port, "type", "veth", "peer", "name", "eth0", "netns", ns,
            ])?;
            ip(&["-n", sw, "link", "set", &port, "master", "br0"])?;
            ip(&["-n", sw, "link", "set", &port, "up"])?;
            let addr = format!("{}/24", Self::address(h));
            ip(&["-n", ns, "addr", "add", &addr, "dev", "eth0"])?;
            ip(&["-n", ns, "link", "set", "eth0", "up"])?;
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(hosts)
    }

    /// Namespaces of earlier runs whose process is gone (killed before its
    /// guard could delete them).
    fn remove_stale() {
        let Ok(out) = Command::new("ip").args(["netns", "list"]).output() else {
            return;
        };
        for line in String::from_utf8_lossy(&out.stdout).lines() {
            let name = line.split_whitespace().next().unwrap_or("");
            let Some(rest) = name.strip_prefix("zscale") else {
                continue;
            };
            let pid = rest.split('-').next().unwrap_or("");
            if pid.parse::<u32>().is_ok() && !std::path::Path::new(&format!("/proc/{pid}")).exists()
            {
                let _ = ip(&["netns", "del", name]);
            }
        }
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        for ns in &self.names {
            let _ = ip(&["netns", "del", ns]);
        }
    }
}

/// Why four hosts cannot be made here, if they cannot.
pub(crate) fn hosts_unavailable() -> Option<String> {
    let root = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("Uid:"))
                .map(|l| l.split_whitespace().nth(1) == Some("0"))
        })
        .unwrap_or(false);
    if !root {
        return Some("not_root".into());
    }
    match Command::new("ip").arg("-V").output() {
        Ok(o) if o.status.success() => None,
        _ => Some("no_ip_command".into()),
    }
}
