//! Memory: the global allocator, and how much of it the kernel backs with huge pages.
//!
//! On Linux tracery allocates through jemalloc, built (`.cargo/config.toml`) to advise
//! transparent huge pages (`madvise(MADV_HUGEPAGE)`) on every mapping it makes, as Embree does
//! on its own large blocks. Most systems give huge pages only where asked (the `madvise`
//! mode); glibc's `malloc` never asks, so with it the BVH build's arrays and the traversal's
//! nodes sat in 4 KB pages, and a build whose memory was out of the caches missed the TLB as
//! well (README, "Huge pages"). [`summary`] says what a process got, for benchmark output.

/// jemalloc (see the module docs).
#[cfg(target_os = "linux")]
#[global_allocator]
static GLOBAL: tikv_jemallocator::Jemalloc = tikv_jemallocator::Jemalloc;

/// The allocator's name.
pub const ALLOCATOR: &str = if cfg!(target_os = "linux") {
    "jemalloc"
} else {
    "the system allocator"
};

/// The mode in brackets of a `transparent_hugepage/enabled` file (`always [madvise] never`).
pub fn parse_thp_mode(text: &str) -> Option<&str> {
    let start = text.find('[')? + 1;
    let len = text[start..].find(']')?;
    Some(&text[start..start + len])
}

/// The `AnonHugePages` line of an `smaps_rollup` file, in bytes.
pub fn parse_anon_huge_bytes(text: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with("AnonHugePages:"))?;
    let mut words = line.split_whitespace().skip(1);
    let kb: u64 = words.next()?.parse().ok()?;
    (words.next() == Some("kB")).then_some(kb * 1024)
}

/// The system's transparent-huge-page mode (`always`, `madvise` or `never`), where the system
/// says.
pub fn thp_mode() -> Option<String> {
    let text = std::fs::read_to_string("/sys/kernel/mm/transparent_hugepage/enabled").ok()?;
    parse_thp_mode(&text).map(str::to_owned)
}

/// Bytes of this process's anonymous memory in huge pages, where the system says.
pub fn huge_page_bytes() -> Option<u64> {
    parse_anon_huge_bytes(&std::fs::read_to_string("/proc/self/smaps_rollup").ok()?)
}

/// One line for benchmark output: the allocator, the system's mode and this process's memory
/// in huge pages.
pub fn summary() -> String {
    let mode = thp_mode().map_or("unknown".to_owned(), |m| m);
    let huge = huge_page_bytes().map_or("unknown".to_owned(), |b| format!("{} MB", b >> 20));
    format!(
        "memory: {ALLOCATOR}, transparent huge pages {mode} on this system, {huge} of this process in huge pages"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bracketed_mode_is_the_one_in_force() {
        assert_eq!(parse_thp_mode("always [madvise] never\n"), Some("madvise"));
        assert_eq!(parse_thp_mode("[always] madvise never"), Some("always"));
        assert_eq!(parse_thp_mode("always madvise never"), None);
    }

    #[test]
    fn anon_huge_pages_are_read_in_bytes() {
        let rollup = "Rss:              106968 kB\nAnonHugePages:     96256 kB\nShmemPmdMapped:        0 kB\n";
        assert_eq!(parse_anon_huge_bytes(rollup), Some(96256 * 1024));
        assert_eq!(parse_anon_huge_bytes("Rss: 12 kB\n"), None);
        assert_eq!(parse_anon_huge_bytes("AnonHugePages: 12 MB\n"), None);
    }

    /// On Linux with huge pages available where asked, a large allocation the process touches
    /// lands in them: the allocator asks. (Skipped where the system gives none.)
    #[test]
    #[cfg(target_os = "linux")]
    fn a_large_allocation_gets_huge_pages_where_the_system_allows() {
        if !matches!(thp_mode().as_deref(), Some("madvise" | "always")) {
            eprintln!("transparent huge pages off on this system: nothing to check");
            return;
        }
        let before = huge_page_bytes().expect("smaps_rollup on Linux");
        let block = std::hint::black_box(vec![1u8; 64 << 20]);
        let after = huge_page_bytes().expect("smaps_rollup on Linux");
        assert!(
            after >= before + (16 << 20),
            "64 MB touched, huge pages {before} -> {after} bytes"
        );
        drop(block);
    }
}
