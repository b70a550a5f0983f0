//! This process's peak resident memory (Linux `VmHWM`), as `holo bench` reports it per case and `holo render`
//! for the whole run (`scripts/memory-guard.sh` holds both against limits in CI).

/// Resets this process's peak resident memory to what is resident now (Linux: `5` into
/// `/proc/self/clear_refs`), so that [`peak_rss_mib`] measures what follows; false where it cannot.
pub fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// Peak resident memory of this process (Linux `VmHWM`), in MiB; `None` where the system does not say.
pub fn peak_rss_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}
