//! A network of the process's own for measurements that must not reach the machine's real
//! network (Link finds its peers by multicast on every interface): a fresh network namespace
//! holding only a loopback interface, up and multicast-capable. Child processes started after
//! it (a Link peer) share it; it ends with the last process in it.

use anyhow::{Context, Result, bail};

/// Moves this process into a network namespace of its own. Call it before any thread starts:
/// without root it needs a user namespace too, which a threaded process cannot enter.
pub fn enter() -> Result<()> {
    // SAFETY: these calls take no pointers.
    let (uid, gid) = unsafe { (libc::geteuid(), libc::getegid()) };
    let flags = if uid == 0 {
        libc::CLONE_NEWNET
    } else {
        libc::CLONE_NEWUSER | libc::CLONE_NEWNET
    };
    // SAFETY: unshare only changes this process's namespaces.
    if unsafe { libc::unshare(flags) } != 0 {
        bail!(
            "cannot make a private network namespace ({}): run as root or allow unprivileged user namespaces",
            std::io::Error::last_os_error()
        );
    }
    if uid != 0 {
        // Root inside the new user namespace is this user outside it.
        std::fs::write("/proc/self/setgroups", "deny").context("denying setgroups")?;
        std::fs::write("/proc/self/uid_map", format!("0 {uid} 1")).context("mapping the user")?;
        std::fs::write("/proc/self/gid_map", format!("0 {gid} 1")).context("mapping the group")?;
    }
    let status = std::process::Command::new("ip")
        .args(["link", "set", "lo", "up", "multicast", "on"])
        .status()
        .context("running `ip` (iproute2) to bring the namespace's loopback up")?;
    if !status.success() {
        bail!("`ip link set lo up multicast on` failed in the private namespace");
    }
    Ok(())
}

/// Whether the only network interface this process sees is loopback (after [`enter`], yes).
pub fn only_loopback() -> bool {
    std::fs::read_to_string("/proc/self/net/dev")
        .map(|t| {
            t.lines()
                .skip(2)
                .filter_map(|l| l.split(':').next())
                .all(|name| name.trim() == "lo")
        })
        .unwrap_or(false)
}
