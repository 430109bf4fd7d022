//! Memory budget. Before anything large is allocated, a render estimates what it will hold
//! (the program itself, the scene, the render-space geometry, the BVH build, the lights, the
//! film and the EXR's planes) and compares it with a limit: `--max-memory`, by default 80 % of the physical
//! memory (or of the cgroup's limit, on a farm node or in a container). A scene that cannot
//! fit fails at once with an error that says where the memory goes, instead of swapping or
//! being killed by the kernel hours into a batch.

use crate::error::{Error, Result};
use std::fmt;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Resident bytes of the program before any scene: code, thread stacks, allocator (the
/// peak of rendering the embedded Cornell box at 64x64 is 11 MB).
pub const PROGRAM_BYTES: u64 = 12 << 20;

/// Share of the machine's memory a render may use by default: the rest is left to the
/// system and to other jobs.
pub const DEFAULT_SHARE: f64 = 0.8;

/// Estimated peak bytes of a render, by what holds them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MemoryEstimate {
    /// The program itself, whatever the scene: its code, thread stacks and allocator.
    pub program: u64,
    /// The loaded scene: vertex data, triangles, texels.
    pub scene: u64,
    /// Render-space copies of meshes flattened more than once (a mesh placed once moves),
    /// what each primitive refers to, and the placements of shared meshes (those meshes
    /// themselves move out of the scene).
    pub geometry: u64,
    /// The BVHs at their build peak: flags, bounds, obvhs's build nodes and the result.
    pub bvh: u64,
    /// Area lights and their selection structures.
    pub lights: u64,
    /// The film's accumulators and the EXR's output planes.
    pub film: u64,
}

impl MemoryEstimate {
    /// The sum of the parts.
    pub fn total(&self) -> u64 {
        self.program + self.scene + self.geometry + self.bvh + self.lights + self.film
    }

    /// Fails with a bad-input error naming `source` when the estimate exceeds `limit`.
    pub fn check(&self, limit: Option<u64>, source: &str) -> Result<()> {
        match limit {
            Some(limit) if self.total() > limit => Err(Error::bad_input(
                source,
                "memory",
                format!(
                    "rendering needs about {} ({self}), more than the limit of {} (--max-memory)",
                    Bytes(self.total()),
                    Bytes(limit)
                ),
            )),
            _ => Ok(()),
        }
    }
}

impl fmt::Display for MemoryEstimate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "program {}, scene {}, geometry {}, BVH build {}, lights {}, film {}",
            Bytes(self.program),
            Bytes(self.scene),
            Bytes(self.geometry),
            Bytes(self.bvh),
            Bytes(self.lights),
            Bytes(self.film)
        )
    }
}

/// A byte count printed with a binary unit, e.g. `1.5 GiB`.
#[derive(Clone, Copy, Debug)]
pub struct Bytes(pub u64);

impl fmt::Display for Bytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
        let mut value = self.0 as f64;
        let mut unit = 0;
        while value >= 1024.0 && unit + 1 < UNITS.len() {
            value /= 1024.0;
            unit += 1;
        }
        if unit == 0 {
            write!(f, "{} B", self.0)
        } else {
            write!(f, "{value:.1} {}", UNITS[unit])
        }
    }
}

/// Parses a `--max-memory` value: bytes with an optional binary suffix (`K`, `M`, `G`, `T`,
/// optionally followed by `iB` or `B`), e.g. `512M`, `1.5G`, `16GiB`; or `off`, no limit
/// (`u64::MAX`).
pub fn parse_limit(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    if t.eq_ignore_ascii_case("off") {
        return Ok(u64::MAX);
    }
    let digits = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (number, unit) = t.split_at(digits);
    let number: f64 = number
        .parse()
        .map_err(|_| format!("{text:?}: expected a size such as 512M, 16G or off"))?;
    let shift = match unit.trim().to_ascii_uppercase().as_str() {
        "" | "B" => 0,
        "K" | "KB" | "KIB" => 10,
        "M" | "MB" | "MIB" => 20,
        "G" | "GB" | "GIB" => 30,
        "T" | "TB" | "TIB" => 40,
        other => return Err(format!("{text:?}: unknown unit {other:?} (K, M, G or T)")),
    };
    let bytes = number * (1u64 << shift) as f64;
    if !(bytes >= 1.0 && bytes < u64::MAX as f64) {
        return Err(format!("{text:?}: must be at least one byte"));
    }
    Ok(bytes as u64)
}

/// The default limit: [`DEFAULT_SHARE`] of the smaller of the physical memory and the
/// cgroup's memory limit (cgroup v2 `memory.max` or v1 `memory.limit_in_bytes`, of this
/// process's own cgroup), or `None` where neither can be read (no limit then).
pub fn default_limit() -> Option<u64> {
    let physical = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| meminfo_total(&text));
    let own = std::fs::read_to_string("/proc/self/cgroup").unwrap_or_default();
    let cgroup = cgroup_limit_files(&own)
        .iter()
        .find_map(|file| std::fs::read_to_string(file).ok())
        .and_then(|text| text.trim().parse::<u64>().ok());
    let available = match (physical, cgroup) {
        (Some(p), Some(c)) => p.min(c),
        (p, c) => p.or(c)?,
    };
    Some((available as f64 * DEFAULT_SHARE) as u64)
}

/// Files that may hold this process's cgroup memory limit, most specific first, from the
/// text of /proc/self/cgroup: v2 (`0::/path` → `/sys/fs/cgroup/path/memory.max`), then v1
/// (`N:memory:/path` → `/sys/fs/cgroup/memory/path/memory.limit_in_bytes`), then the roots
/// (what a container sees when its own cgroup is mounted there). "max" (v2) does not parse
/// and v1's "unlimited" is a huge number: both leave the physical memory to decide.
fn cgroup_limit_files(proc_self_cgroup: &str) -> Vec<String> {
    let mut files = Vec::new();
    for line in proc_self_cgroup.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(_), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        let path = path.trim_end_matches('/');
        if path.split('/').any(|p| p == "..") {
            continue;
        }
        if controllers.is_empty() {
            files.push(format!("/sys/fs/cgroup{path}/memory.max"));
        } else if controllers.split(',').any(|c| c == "memory") {
            files.push(format!("/sys/fs/cgroup/memory{path}/memory.limit_in_bytes"));
        }
    }
    files.push("/sys/fs/cgroup/memory.max".into());
    files.push("/sys/fs/cgroup/memory/memory.limit_in_bytes".into());
    files
}

/// The limit this process works under (set once by the command line from `--max-memory`
/// or [`default_limit`]); 0 is none. Readers consult it before decoding anything whose
/// header declares its size (images), so a small file cannot make them allocate gigabytes.
static PROCESS_LIMIT: AtomicU64 = AtomicU64::new(0);

/// Sets the limit [`check_allocation`] holds readers to (`None`: no limit).
pub fn set_process_limit(limit: Option<u64>) {
    PROCESS_LIMIT.store(limit.unwrap_or(0), Ordering::Relaxed);
}

/// The limit set by [`set_process_limit`], if any.
pub fn process_limit() -> Option<u64> {
    match PROCESS_LIMIT.load(Ordering::Relaxed) {
        0 | u64::MAX => None,
        limit => Some(limit),
    }
}

/// The texture memory chosen by `--texture-memory` (0: half of the process limit).
static TEXTURE_MEMORY: AtomicU64 = AtomicU64::new(0);

/// Whether the render builds MIP pyramids (`--texture-filter mip`), so that textures need a
/// third more memory for each way they are read; until told, assumed.
static MIP_PYRAMIDS: AtomicBool = AtomicBool::new(true);

/// Sets the texture memory [`texture_memory`] answers (`None`: half of the process limit)
/// and whether textures will have MIP pyramids ([`mip_pyramids`]).
pub fn set_texture_memory(bytes: Option<u64>, pyramids: bool) {
    TEXTURE_MEMORY.store(bytes.unwrap_or(0), Ordering::Relaxed);
    MIP_PYRAMIDS.store(pyramids, Ordering::Relaxed);
}

/// Whether the textures of this process's render will have MIP pyramids.
pub fn mip_pyramids() -> bool {
    MIP_PYRAMIDS.load(Ordering::Relaxed)
}

/// The most that a scene's textures may hold in memory, decoded and with their MIP
/// pyramids, before they are read through a tile cache of this size instead
/// (`scene::texture_cache`): `--texture-memory`, by default half of the process limit;
/// `None` without either.
pub fn texture_memory() -> Option<u64> {
    match TEXTURE_MEMORY.load(Ordering::Relaxed) {
        0 => process_limit().map(|limit| limit / 2),
        u64::MAX => None,
        bytes => Some(bytes),
    }
}

/// Refuses to allocate `bytes` for `what` when that alone exceeds the process limit.
pub fn check_allocation(bytes: u64, what: &str) -> std::result::Result<(), String> {
    check_allocation_within(bytes, what, process_limit())
}

/// Refuses to allocate `bytes` for `what` when that alone exceeds `limit`.
pub fn check_allocation_within(
    bytes: u64,
    what: &str,
    limit: Option<u64>,
) -> std::result::Result<(), String> {
    match limit {
        Some(limit) if bytes > limit => Err(format!(
            "{what} would need {} to decode, more than the limit of {} (--max-memory)",
            Bytes(bytes),
            Bytes(limit)
        )),
        _ => Ok(()),
    }
}

/// `MemTotal` of /proc/meminfo in bytes.
fn meminfo_total(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_parse_with_binary_units() {
        assert_eq!(parse_limit("off"), Ok(u64::MAX));
        assert_eq!(parse_limit("4096"), Ok(4096));
        assert_eq!(parse_limit("512M"), Ok(512 << 20));
        assert_eq!(parse_limit("1.5G"), Ok(3 << 29));
        assert_eq!(parse_limit("16GiB"), Ok(16 << 30));
        assert_eq!(parse_limit("2 tb"), Ok(2 << 40));
        for bad in ["", "G", "-1G", "0", "12X", "1e3M", "NaN"] {
            assert!(parse_limit(bad).is_err(), "{bad:?} accepted");
        }
    }

    #[test]
    fn cgroup_limits_are_looked_up_for_v1_and_v2() {
        let v2 = cgroup_limit_files("0::/user.slice/job-7\n");
        assert_eq!(v2[0], "/sys/fs/cgroup/user.slice/job-7/memory.max");
        let v1 = cgroup_limit_files("12:cpu,cpuacct:/x\n4:memory:/docker/abc\n");
        assert_eq!(
            v1[0],
            "/sys/fs/cgroup/memory/docker/abc/memory.limit_in_bytes"
        );
        assert_eq!(v1.len(), 3);
        assert!(cgroup_limit_files("0::/../../etc\n").len() == 2);
        assert!(
            cgroup_limit_files("")
                .contains(&"/sys/fs/cgroup/memory/memory.limit_in_bytes".to_string())
        );
    }

    #[test]
    fn physical_memory_reads_from_meminfo() {
        let text = "MemTotal:       24576000 kB\nMemFree:  100 kB\n";
        assert_eq!(meminfo_total(text), Some(24_576_000 * 1024));
        assert_eq!(meminfo_total("nothing"), None);
    }

    #[test]
    fn an_estimate_over_the_limit_names_the_parts() {
        let estimate = MemoryEstimate {
            program: 0,
            scene: 1 << 30,
            geometry: 2 << 30,
            bvh: 3 << 30,
            lights: 0,
            film: 512 << 20,
        };
        assert!(estimate.check(Some(7 << 30), "s.glb").is_ok());
        assert!(estimate.check(None, "s.glb").is_ok());
        let message = estimate
            .check(Some(6 << 30), "s.glb")
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("6.5 GiB")
                && message.contains("BVH build 3.0 GiB")
                && message.contains("limit of 6.0 GiB"),
            "{message}"
        );
    }
}
