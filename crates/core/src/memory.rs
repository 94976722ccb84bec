//! The process's allocator settings (glibc's malloc; elsewhere nothing to set): large buffers
//! straight from the system and back, freed smaller ones kept for the next allocation during a
//! build, and handed back when the daemon goes idle.

/// Buffers from this size up (images, mip levels, blocks) are mapped from the system and
/// unmapped when freed. glibc's default raises its threshold to the largest buffer freed so
/// far, so a build's freed 16 MiB images are kept in its heaps, and peak memory grows with every
/// texture baked on another thread: four 2048² albedos peaked at 315 MB, with a fixed threshold
/// 260 MB.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const MAPPED_FROM_BYTES: libc::c_int = 1 << 20;

/// The most free memory a heap keeps at its top before it gives it back to the system. A
/// build allocates and frees many smaller short-lived buffers (a preview view's render target,
/// depth buffer and readback, each resolved image), and with glibc's default (128 KiB, fixed
/// once the threshold above is set) each free shrank a heap, and the next buffer faulted its
/// pages in again, zeroed by the kernel: on the oak's four-level `Auto` chain 0.7 to 1.3 million
/// page faults and 1.4 to 2.5 s of system time in a build of 8.5 to 10.1 s (2 cores, llvmpipe).
/// Kept, 0.26 million faults and 0.8 to 1.1 s, the build 7.9 to 8.1 s, its peak 15 MiB higher
/// (445 MiB). 32 MiB kept as many faults away as 512 MiB did (0.26 to 0.28 million), and bounds
/// what an idle heap holds.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const KEPT_FREE_BYTES: libc::c_int = 32 << 20;

/// The most heaps (arenas) the threads share. glibc makes up to eight per core, each keeping
/// its own freed memory (up to [`KEPT_FREE_BYTES`] at its top, and whatever lies between live
/// buffers), so the resident memory of a long run grew past its live heap with every thread that
/// had allocated: a daemon's first batch under a 1024 MiB budget (2 cores) held 459 MiB of heap
/// at its peak on 64 `make_level` Materials and 481 MiB on 256, but peaked at 497 and 561 MiB
/// resident (+13 %); with two heaps at 461 and 488 MiB (+6 %), in the same wall time (the
/// threads' small allocations come from their own caches without taking a heap's lock).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const HEAPS: libc::c_int = 2;

/// Sets the allocator's thresholds ([`MAPPED_FROM_BYTES`], [`KEPT_FREE_BYTES`]) and its number of
/// heaps ([`HEAPS`]). Call once, before the worker threads start.
pub fn configure_allocator() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets an allocator parameter.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MAPPED_FROM_BYTES);
        libc::mallopt(libc::M_TRIM_THRESHOLD, KEPT_FREE_BYTES);
        libc::mallopt(libc::M_ARENA_MAX, HEAPS);
    }
}

/// Hands the free memory the heaps kept back to the system: the daemon calls it when idle, so
/// that a build's peak is not held between edits.
pub fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only returns free pages to the system.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// The process's memory budget when neither `--memory-mib` nor `limits: (memory_mib: …)` sets
/// one: half the machine's memory (`MemTotal`), or 8 GiB where it cannot be read.
pub fn default_budget() -> u64 {
    machine_memory().map_or(8 << 30, |total| total / 2)
}

/// The machine's memory in bytes (Linux: `/proc/meminfo`'s `MemTotal`).
pub fn machine_memory() -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = meminfo.lines().find(|line| line.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib << 10)
}

/// The process's resident memory now, in bytes (Linux: `/proc/self/statm`; `None` elsewhere).
pub fn resident_bytes() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    // SAFETY: sysconf only reads a system constant.
    #[cfg(unix)]
    let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) }.max(1) as u64;
    #[cfg(not(unix))]
    let page = 4096;
    Some(pages * page)
}
