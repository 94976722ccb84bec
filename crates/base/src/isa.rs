//! The instruction-set level cirrus's CPU kernels run at (the ISPC block encoders, the BC4
//! search, the ray kernels): the best this CPU has, or a lower level chosen once for the whole
//! process (`--isa`, `CIRRUS_ISA`), so that a machine with AVX-512 can measure what one without
//! it gets, and a user can rule out a miscompiled wide path.

use std::fmt;
use std::str::FromStr;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::OnceLock;

/// An x86-64 instruction-set level, lowest first. On other architectures every level runs the
/// portable kernels, and `detected_isa` is `Portable`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum IsaLevel {
    /// SSE2 (every x86-64 CPU), or the portable Rust kernels elsewhere.
    Portable,
    /// SSE4.2.
    Sse4,
    /// AVX2 and FMA (x86-64-v3: Haswell, Zen 1 and later).
    Avx2,
    /// AVX-512 F, BW, DQ and VL (Skylake-X, Ice Lake, Zen 4 and later).
    Avx512,
}

impl IsaLevel {
    pub const ALL: [IsaLevel; 4] = [IsaLevel::Portable, IsaLevel::Sse4, IsaLevel::Avx2, IsaLevel::Avx512];

    pub fn name(self) -> &'static str {
        match self {
            IsaLevel::Portable => "sse2",
            IsaLevel::Sse4 => "sse4",
            IsaLevel::Avx2 => "avx2",
            IsaLevel::Avx512 => "avx512",
        }
    }

    fn from_index(index: u8) -> IsaLevel {
        IsaLevel::ALL[usize::from(index).min(IsaLevel::ALL.len() - 1)]
    }
}

impl fmt::Display for IsaLevel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for IsaLevel {
    type Err = String;

    fn from_str(text: &str) -> Result<IsaLevel, String> {
        match text.trim().to_ascii_lowercase().as_str() {
            "sse2" | "portable" => Ok(IsaLevel::Portable),
            "sse4" | "sse4.2" => Ok(IsaLevel::Sse4),
            "avx2" => Ok(IsaLevel::Avx2),
            "avx512" | "avx-512" | "native" => Ok(IsaLevel::Avx512),
            other => Err(format!("`{other}` is not an instruction-set level (sse2, sse4, avx2 or avx512)")),
        }
    }
}

/// The best level this CPU runs.
pub fn detected_isa() -> IsaLevel {
    static DETECTED: OnceLock<IsaLevel> = OnceLock::new();
    *DETECTED.get_or_init(detect)
}

#[cfg(target_arch = "x86_64")]
fn detect() -> IsaLevel {
    use std::arch::is_x86_feature_detected as has;
    if has!("avx512f") && has!("avx512bw") && has!("avx512dq") && has!("avx512vl") && has!("avx2") && has!("fma") {
        IsaLevel::Avx512
    } else if has!("avx2") && has!("fma") {
        IsaLevel::Avx2
    } else if has!("sse4.2") {
        IsaLevel::Sse4
    } else {
        IsaLevel::Portable
    }
}

#[cfg(not(target_arch = "x86_64"))]
fn detect() -> IsaLevel {
    IsaLevel::Portable
}

/// The highest level the kernels may use, as an index into `IsaLevel::ALL` (no limit: the top).
static LIMIT: AtomicU8 = AtomicU8::new(IsaLevel::Avx512 as u8);

/// Keeps every kernel at or below `level` from now on (a level above the CPU's changes nothing).
/// Meant to be called once, before any work starts.
pub fn limit_isa(level: IsaLevel) {
    LIMIT.store(level as u8, Ordering::Relaxed);
}

/// The level the kernels run at: the CPU's, or the limit when that is lower.
pub fn kernel_isa() -> IsaLevel {
    detected_isa().min(IsaLevel::from_index(LIMIT.load(Ordering::Relaxed)))
}

/// Whether the kernels may use AVX2 and FMA.
pub fn avx2_allowed() -> bool {
    kernel_isa() >= IsaLevel::Avx2
}
