//! How much memory a job may still take, and refusing jobs (or allocations) that would not fit,
//! with a message that names the limit that binds.
//!
//! `MemAvailable` alone is not enough: it is the whole host's, while a job is often held to less
//! by `ulimit -v` (RLIMIT_AS, which counts mapped address space, so allocations fail early),
//! `ulimit -d` (RLIMIT_DATA) or a cgroup (Slurm, Kubernetes, `docker --memory`, whose OOM killer
//! ends the job without a message). [`available`] takes the smallest of them. Everything is read
//! from `/proc` and `/sys`, so no libc is needed; whatever is missing or unreadable is skipped.

use std::fmt;
use std::fs;
use std::path::{Path, PathBuf};

/// What every job needs beside its arrays (the binary, the thread pool, the scene): 32 MiB.
pub const BASE_BYTES: u64 = 32 << 20;

/// A cgroup v1 limit at or above this means none (the kernel reports "unlimited" as
/// `9223372036854771712` with 4 KiB pages, a little less than `i64::MAX` with larger pages).
const V1_UNLIMITED: u64 = 1 << 62;

/// The limit that bounds a job's memory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LimitSource {
    /// `MemAvailable` in `/proc/meminfo`: the whole host's, shared with every other process.
    MemAvailable,
    /// RLIMIT_AS (`ulimit -v`) less the address space already mapped (`VmSize`).
    AddressSpace,
    /// RLIMIT_DATA (`ulimit -d`) less the data segment already mapped (`VmData`).
    DataSegment,
    /// A cgroup v2 `memory.max` (this file) less `memory.current`.
    CgroupV2 { path: PathBuf },
    /// A cgroup v1 `memory.limit_in_bytes` (this file) less `memory.usage_in_bytes`.
    CgroupV1 { path: PathBuf },
    /// A cap the user set (`--max-memory`, a `max_memory` argument).
    MaxMemoryFlag,
}

impl LimitSource {
    /// What to do about this limit, as the end of "lower --res or ...".
    pub fn remedy(&self) -> &'static str {
        match self {
            LimitSource::MemAvailable => "free memory on this machine",
            LimitSource::AddressSpace => "raise ulimit -v",
            LimitSource::DataSegment => "raise ulimit -d",
            LimitSource::CgroupV2 { .. } | LimitSource::CgroupV1 { .. } => {
                "raise the job's memory limit (Slurm --mem, docker --memory, a pod's limits)"
            }
            LimitSource::MaxMemoryFlag => "raise --max-memory",
        }
    }
}

impl fmt::Display for LimitSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LimitSource::MemAvailable => f.write_str("MemAvailable in /proc/meminfo"),
            LimitSource::AddressSpace => f.write_str("the address-space limit (ulimit -v)"),
            LimitSource::DataSegment => f.write_str("the data-segment limit (ulimit -d)"),
            LimitSource::CgroupV2 { path } => write!(
                f,
                "the cgroup's memory.max ({}) less memory.current",
                path.display()
            ),
            LimitSource::CgroupV1 { path } => write!(
                f,
                "the cgroup's memory.limit_in_bytes ({}) less memory.usage_in_bytes",
                path.display()
            ),
            LimitSource::MaxMemoryFlag => f.write_str("--max-memory"),
        }
    }
}

/// The bytes a job may still take, and the limit that bounds them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MemoryLimit {
    pub bytes: u64,
    pub source: LimitSource,
}

impl MemoryLimit {
    /// "3.81 GiB is left under the address-space limit (ulimit -v)", worded for the source.
    fn phrase(&self) -> String {
        let g = gib(self.bytes);
        match self.source {
            LimitSource::MaxMemoryFlag => format!("--max-memory allows {g:.2} GiB"),
            LimitSource::MemAvailable => {
                format!("{g:.2} GiB is available (MemAvailable in /proc/meminfo)")
            }
            _ => format!("{g:.2} GiB is left under {}", self.source),
        }
    }
}

/// The memory this process may still take: the smallest headroom among `MemAvailable`,
/// `ulimit -v`, `ulimit -d` and the cgroup limits of this process's cgroup and its ancestors.
/// `None` when none can be read (and on anything but Linux).
pub fn available() -> Option<MemoryLimit> {
    if cfg!(target_os = "linux") {
        available_under(Path::new("/"))
    } else {
        None
    }
}

/// [`available`], reading `proc/` and `sys/` under `root` instead of `/` (for tests).
pub fn available_under(root: &Path) -> Option<MemoryLimit> {
    let cgroups = read(&root.join("proc/self/cgroup"));
    let cgroups = cgroups.as_deref().unwrap_or("");
    [
        mem_available(root),
        rlimit_headroom(
            root,
            "Max address space",
            "VmSize:",
            LimitSource::AddressSpace,
        ),
        rlimit_headroom(root, "Max data size", "VmData:", LimitSource::DataSegment),
        cgroup_v2(root, cgroups),
        cgroup_v1(root, cgroups),
    ]
    .into_iter()
    .flatten()
    .min_by_key(|l| l.bytes)
}

fn read(path: &Path) -> Option<String> {
    fs::read_to_string(path).ok()
}

fn read_u64(path: &Path) -> Option<u64> {
    read(path)?.trim().parse().ok()
}

/// The number after `key` in a `key value [kB]` file (`/proc/meminfo`, `/proc/self/status`,
/// `memory.stat`).
fn field(text: &str, key: &str) -> Option<u64> {
    text.lines().find_map(|l| {
        let mut words = l.split_whitespace();
        if words.next()? != key {
            return None;
        }
        words.next()?.parse().ok()
    })
}

fn mem_available(root: &Path) -> Option<MemoryLimit> {
    let kib = field(&read(&root.join("proc/meminfo"))?, "MemAvailable:")?;
    Some(MemoryLimit {
        bytes: kib.saturating_mul(1024),
        source: LimitSource::MemAvailable,
    })
}

/// A soft rlimit from `/proc/self/limits` less what `/proc/self/status` says is already used
/// (`VmSize` for RLIMIT_AS, `VmData` for RLIMIT_DATA): both count mappings, not resident pages,
/// so a job is refused at the limit however little of it is touched. No usage counts as 0.
fn rlimit_headroom(
    root: &Path,
    limit: &str,
    usage: &str,
    source: LimitSource,
) -> Option<MemoryLimit> {
    let limits = read(&root.join("proc/self/limits"))?;
    let soft = limits
        .lines()
        .find_map(|l| l.strip_prefix(limit))?
        .split_whitespace()
        .next()?;
    let soft: u64 = soft.parse().ok()?; // "unlimited" (or anything else) is no limit
    let used_kib = read(&root.join("proc/self/status"))
        .and_then(|s| field(&s, usage))
        .unwrap_or(0);
    Some(MemoryLimit {
        bytes: soft.saturating_sub(used_kib.saturating_mul(1024)),
        source,
    })
}

/// `mount` joined with each leading part of `rel`: the root first, the cgroup itself last.
/// A path that climbs (`..`, seen from outside a cgroup namespace) gives only the root. Walking
/// up also finds the limit where the mount's root is the job's own cgroup (a container without
/// a cgroup namespace), as the deeper folders then do not exist.
fn cgroup_dirs(mount: &Path, rel: &str) -> Vec<PathBuf> {
    let parts: Vec<&str> = rel.split('/').filter(|p| !p.is_empty()).collect();
    let parts = if parts.iter().any(|p| *p == "." || *p == "..") {
        &[][..]
    } else {
        &parts[..]
    };
    let mut dir = mount.to_path_buf();
    let mut dirs = vec![dir.clone()];
    for p in parts {
        dir.push(p);
        dirs.push(dir.clone());
    }
    dirs
}

/// What a cgroup holds that the job cannot get back: `usage` less the inactive page cache in
/// `memory.stat` (`key`), which the kernel reclaims before it OOM-kills (kubelet's "working
/// set"); without it a job that has just written big files would be refused for its cache.
fn cgroup_used(dir: &Path, usage: u64, key: &str) -> u64 {
    let inactive = read(&dir.join("memory.stat"))
        .and_then(|s| field(&s, key))
        .unwrap_or(0);
    usage.saturating_sub(inactive)
}

/// cgroup v2 (`0::/path` in `/proc/self/cgroup`): each level's `memory.max` (`max` = none)
/// less its `memory.current`, the smallest; a limit on any ancestor binds the job too.
fn cgroup_v2(root: &Path, cgroups: &str) -> Option<MemoryLimit> {
    let rel = cgroups.lines().find_map(|l| l.strip_prefix("0::"))?;
    cgroup_dirs(&root.join("sys/fs/cgroup"), rel)
        .into_iter()
        .filter_map(|dir| {
            let path = dir.join("memory.max");
            let max: u64 = read(&path)?.trim().parse().ok()?; // "max" is no limit
            let used = cgroup_used(
                &dir,
                read_u64(&dir.join("memory.current"))?,
                "inactive_file",
            );
            Some(MemoryLimit {
                bytes: max.saturating_sub(used),
                source: LimitSource::CgroupV2 { path },
            })
        })
        .min_by_key(|l| l.bytes)
}

/// cgroup v1 (the `memory` controller's line of `/proc/self/cgroup`): each level's
/// `memory.limit_in_bytes` (a huge value = none) less its `memory.usage_in_bytes`, the smallest.
fn cgroup_v1(root: &Path, cgroups: &str) -> Option<MemoryLimit> {
    let rel = cgroups.lines().find_map(|l| {
        let mut parts = l.splitn(3, ':');
        let (_, controllers, rel) = (parts.next()?, parts.next()?, parts.next()?);
        controllers.split(',').any(|c| c == "memory").then_some(rel)
    })?;
    cgroup_dirs(&root.join("sys/fs/cgroup/memory"), rel)
        .into_iter()
        .filter_map(|dir| {
            let path = dir.join("memory.limit_in_bytes");
            let limit = read_u64(&path).filter(|&b| b < V1_UNLIMITED)?;
            let usage = read_u64(&dir.join("memory.usage_in_bytes"))?;
            let used = cgroup_used(&dir, usage, "total_inactive_file");
            Some(MemoryLimit {
                bytes: limit.saturating_sub(used),
                source: LimitSource::CgroupV1 { path },
            })
        })
        .min_by_key(|l| l.bytes)
}

/// A size for `--max-memory`: bytes, or a number with `K`, `M`, `G` or `T` (powers of 1024,
/// optionally followed by `B` or `iB`).
pub fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let (digits, unit) = match t.char_indices().find(|(_, c)| c.is_ascii_alphabetic()) {
        Some((i, _)) => (&t[..i], &t[i..]),
        None => (t, ""),
    };
    let scale: u64 = match unit.to_ascii_uppercase().trim_end_matches(['B', 'I']) {
        "" => 1,
        "K" => 1 << 10,
        "M" => 1 << 20,
        "G" => 1 << 30,
        "T" => 1 << 40,
        _ => {
            return Err(format!(
                "`{s}`: expected bytes or a number with K, M, G or T"
            ))
        }
    };
    let n: f64 = digits
        .trim()
        .parse()
        .map_err(|_| format!("`{s}`: expected bytes or a number with K, M, G or T"))?;
    if !(n.is_finite() && n > 0.0 && n * scale as f64 <= u64::MAX as f64) {
        return Err(format!("`{s}`: must be a positive size"));
    }
    Ok((n * scale as f64) as u64)
}

fn gib(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 30) as f64
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Failure {
    /// [`check`]: the estimate exceeds this limit.
    Estimate(MemoryLimit),
    /// [`try_alloc_vec`], [`try_with_capacity`]: the allocator refused; what [`available`] said.
    Allocation(Option<MemoryLimit>),
}

/// A job or an allocation that does not fit in the memory left.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MemoryError {
    what: String,
    need: u64,
    failure: Failure,
}

impl MemoryError {
    /// The job or array, as the caller named it (`--res 20000x20000`).
    pub fn what(&self) -> &str {
        &self.what
    }

    /// The bytes the job would need (with [`BASE_BYTES`]) or the allocation asked for.
    pub fn need(&self) -> u64 {
        self.need
    }

    /// The limit that refused the job, or the one in force when an allocation failed.
    pub fn limit(&self) -> Option<&MemoryLimit> {
        match &self.failure {
            Failure::Estimate(l) => Some(l),
            Failure::Allocation(l) => l.as_ref(),
        }
    }

    /// "Lower --res or raise ulimit -v.": the flag is `what`'s first word when it is one.
    fn advice(&self, f: &mut fmt::Formatter<'_>, limit: &MemoryLimit) -> fmt::Result {
        match self
            .what
            .split_whitespace()
            .next()
            .filter(|w| w.starts_with('-'))
        {
            Some(flag) => write!(f, " Lower {flag} or {}.", limit.source.remedy()),
            None => write!(f, " Make the job smaller or {}.", limit.source.remedy()),
        }
    }
}

impl fmt::Display for MemoryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.failure {
            Failure::Estimate(limit) => {
                write!(
                    f,
                    "{}: the job would need about {:.2} GiB of memory; {}.",
                    self.what,
                    gib(self.need),
                    limit.phrase()
                )?;
                self.advice(f, limit)
            }
            Failure::Allocation(limit) => {
                write!(
                    f,
                    "{}: could not allocate {} bytes ({:.2} GiB)",
                    self.what,
                    self.need,
                    gib(self.need)
                )?;
                match limit {
                    Some(l) => {
                        write!(f, "; {}.", l.phrase())?;
                        if l.bytes < self.need {
                            self.advice(f, l)?;
                        }
                        Ok(())
                    }
                    None => f.write_str("."),
                }
            }
        }
    }
}

impl std::error::Error for MemoryError {}

/// Refuses a job whose estimate `need` (bytes; [`BASE_BYTES`] is added here) exceeds
/// `max_memory` or what [`available`] says is left. `what` names the flag and value that set
/// the size (`--res 20000x20000`); the message suggests lowering that flag.
pub fn check(what: &str, need: u64, max_memory: Option<u64>) -> Result<(), MemoryError> {
    check_against(what, need, max_memory, available())
}

/// [`check`] for a job that already holds `held` bytes, allocated before its size was known (a
/// loaded scene's meshes and BVH): what is left on the machine must take `need`, as it already
/// excludes `held`; `max_memory` must take both.
pub fn check_more(
    what: &str,
    need: u64,
    held: u64,
    max_memory: Option<u64>,
) -> Result<(), MemoryError> {
    if max_memory.is_some() {
        check_against(what, need.saturating_add(held), max_memory, None)?;
    }
    check_against(what, need, None, available())
}

fn check_against(
    what: &str,
    need: u64,
    max_memory: Option<u64>,
    machine: Option<MemoryLimit>,
) -> Result<(), MemoryError> {
    let need = need.saturating_add(BASE_BYTES);
    let cap = max_memory.map(|bytes| MemoryLimit {
        bytes,
        source: LimitSource::MaxMemoryFlag,
    });
    let limit = match (cap, machine) {
        (Some(c), Some(m)) => Some(if c.bytes <= m.bytes { c } else { m }),
        (c, m) => c.or(m),
    };
    match limit {
        Some(l) if need > l.bytes => Err(MemoryError {
            what: what.to_owned(),
            need,
            failure: Failure::Estimate(l),
        }),
        _ => Ok(()),
    }
}

fn alloc_error<T>(len: usize, what: &str) -> MemoryError {
    MemoryError {
        what: what.to_owned(),
        need: (len as u64).saturating_mul(std::mem::size_of::<T>() as u64),
        failure: Failure::Allocation(available()),
    }
}

/// An empty `Vec` with room for `len` elements, or an error naming `what` and the limit where
/// the allocator refuses (under `ulimit -v` a too-large allocation fails rather than aborts).
pub fn try_with_capacity<T>(len: usize, what: &str) -> Result<Vec<T>, MemoryError> {
    let mut v = Vec::new();
    v.try_reserve_exact(len)
        .map_err(|_| alloc_error::<T>(len, what))?;
    Ok(v)
}

/// `vec![value; len]`, or an error naming `what` and the limit where the allocator refuses.
pub fn try_alloc_vec<T: Clone>(len: usize, value: T, what: &str) -> Result<Vec<T>, MemoryError> {
    let mut v = try_with_capacity(len, what)?;
    v.resize(len, value);
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    const GIB: u64 = 1 << 30;

    /// A fake filesystem root in the temporary folder, removed on drop.
    struct Fake {
        root: PathBuf,
    }

    impl Fake {
        fn new(name: &str) -> Self {
            static N: AtomicUsize = AtomicUsize::new(0);
            let n = N.fetch_add(1, Ordering::Relaxed);
            let root = std::env::temp_dir()
                .join(format!("striae-memory-{}-{name}-{n}", std::process::id()));
            let _ = fs::remove_dir_all(&root);
            fs::create_dir_all(&root).unwrap();
            Fake { root }
        }

        fn file(&self, rel: &str, text: &str) -> &Self {
            let p = self.root.join(rel);
            fs::create_dir_all(p.parent().unwrap()).unwrap();
            fs::write(p, text).unwrap();
            self
        }

        fn meminfo(&self, kib: u64) -> &Self {
            self.file(
                "proc/meminfo",
                &format!("MemTotal:       99999999 kB\nMemFree:  1 kB\nMemAvailable:   {kib} kB\n"),
            )
        }

        fn limits(&self, address_space: &str, data: &str) -> &Self {
            self.file(
                "proc/self/limits",
                &format!(
                    "Limit                     Soft Limit           Hard Limit           Units     \n\
                     Max cpu time              unlimited            unlimited            seconds   \n\
                     Max data size             {data:<20} unlimited            bytes     \n\
                     Max stack size            8388608              unlimited            bytes     \n\
                     Max address space         {address_space:<20} unlimited            bytes     \n"
                ),
            )
        }

        fn status(&self, vm_size_kib: u64, vm_data_kib: u64) -> &Self {
            self.file(
                "proc/self/status",
                &format!(
                    "Name:\tmemtest\nVmPeak:\t 99999999 kB\nVmSize:\t {vm_size_kib} kB\n\
                     VmRSS:\t 1000 kB\nVmData:\t {vm_data_kib} kB\n"
                ),
            )
        }

        fn avail(&self) -> Option<MemoryLimit> {
            available_under(&self.root)
        }
    }

    impl Drop for Fake {
        fn drop(&mut self) {
            let _ = fs::remove_dir_all(&self.root);
        }
    }

    #[test]
    fn nothing_readable_is_none() {
        let f = Fake::new("empty");
        assert_eq!(f.avail(), None);
    }

    #[test]
    fn mem_available_binds_alone() {
        let f = Fake::new("meminfo");
        f.meminfo(4 << 20)
            .limits("unlimited", "unlimited")
            .status(1 << 20, 1 << 19);
        assert_eq!(
            f.avail(),
            Some(MemoryLimit {
                bytes: 4 * GIB,
                source: LimitSource::MemAvailable
            })
        );
    }

    #[test]
    fn address_space_binds_less_what_is_mapped() {
        let f = Fake::new("as");
        f.meminfo(16 << 20)
            .limits("4000000000", "unlimited")
            .status(1_000_000, 100);
        let l = f.avail().unwrap();
        assert_eq!(
            l,
            MemoryLimit {
                bytes: 4_000_000_000 - 1_024_000_000,
                source: LimitSource::AddressSpace
            }
        );
        // Without a status file the whole limit is the headroom.
        let g = Fake::new("as-nostatus");
        g.meminfo(16 << 20).limits("4000000000", "unlimited");
        assert_eq!(g.avail().unwrap().bytes, 4_000_000_000);
    }

    #[test]
    fn data_segment_binds_less_vm_data() {
        let f = Fake::new("data");
        f.meminfo(16 << 20)
            .limits("8000000000", "3000000000")
            .status(5_000_000, 1_000_000);
        let l = f.avail().unwrap();
        assert_eq!(
            l,
            MemoryLimit {
                bytes: 3_000_000_000 - 1_024_000_000,
                source: LimitSource::DataSegment
            }
        );
    }

    #[test]
    fn larger_limits_do_not_bind() {
        let f = Fake::new("larger");
        f.meminfo(1 << 20)
            .limits("40000000000", "30000000000")
            .status(1000, 1000);
        assert_eq!(f.avail().unwrap().source, LimitSource::MemAvailable);
    }

    #[test]
    fn cgroup_v2_binds_and_honours_ancestors() {
        let f = Fake::new("v2");
        f.meminfo(16 << 20)
            .limits("unlimited", "unlimited")
            .file("proc/self/cgroup", "0::/slurm/job_7/step_0\n")
            .file("sys/fs/cgroup/slurm/job_7/step_0/memory.max", "max\n")
            .file(
                "sys/fs/cgroup/slurm/job_7/step_0/memory.current",
                "1073741824\n",
            )
            .file("sys/fs/cgroup/slurm/job_7/memory.max", "4294967296\n")
            .file("sys/fs/cgroup/slurm/job_7/memory.current", "1073741824\n")
            .file("sys/fs/cgroup/slurm/memory.max", "8589934592\n")
            .file("sys/fs/cgroup/slurm/memory.current", "1073741824\n");
        let path = f.root.join("sys/fs/cgroup/slurm/job_7/memory.max");
        assert_eq!(
            f.avail(),
            Some(MemoryLimit {
                bytes: 3 * GIB,
                source: LimitSource::CgroupV2 { path }
            })
        );

        // The leaf binds when it is tighter.
        f.file(
            "sys/fs/cgroup/slurm/job_7/step_0/memory.max",
            "2147483648\n",
        );
        let path = f.root.join("sys/fs/cgroup/slurm/job_7/step_0/memory.max");
        assert_eq!(
            f.avail(),
            Some(MemoryLimit {
                bytes: GIB,
                source: LimitSource::CgroupV2 { path }
            })
        );
    }

    #[test]
    fn cgroup_v2_root_mount_and_inactive_cache() {
        // A container without a cgroup namespace: /proc/self/cgroup names a path that is not
        // under the mount, whose root is the container's own cgroup.
        let f = Fake::new("v2-root");
        f.meminfo(16 << 20)
            .file("proc/self/cgroup", "0::/system.slice/docker-abc.scope\n")
            .file("sys/fs/cgroup/memory.max", "2147483648\n")
            .file("sys/fs/cgroup/memory.current", "1610612736\n")
            .file(
                "sys/fs/cgroup/memory.stat",
                "anon 536870912\nfile 1073741824\nactive_file 536870912\ninactive_file 536870912\n",
            );
        let path = f.root.join("sys/fs/cgroup/memory.max");
        // 2 GiB less (1.5 GiB used less 0.5 GiB inactive cache).
        assert_eq!(
            f.avail(),
            Some(MemoryLimit {
                bytes: GIB,
                source: LimitSource::CgroupV2 { path }
            })
        );
    }

    #[test]
    fn cgroup_v1_binds_huge_means_none() {
        let f = Fake::new("v1");
        f.meminfo(16 << 20)
            .file(
                "proc/self/cgroup",
                "9:name=systemd:/\n4:memory:/kube/pod1\n3:cpu,cpuacct:/kube/pod1\n0::/\n",
            )
            .file(
                "sys/fs/cgroup/memory/memory.limit_in_bytes",
                "9223372036854771712\n",
            )
            .file("sys/fs/cgroup/memory/memory.usage_in_bytes", "9000000000\n")
            .file(
                "sys/fs/cgroup/memory/kube/memory.limit_in_bytes",
                "6442450944\n",
            )
            .file(
                "sys/fs/cgroup/memory/kube/memory.usage_in_bytes",
                "1073741824\n",
            )
            .file(
                "sys/fs/cgroup/memory/kube/memory.stat",
                "inactive_file 0\ntotal_inactive_file 1073741824\n",
            )
            .file(
                "sys/fs/cgroup/memory/kube/pod1/memory.limit_in_bytes",
                "9223372036854771712\n",
            )
            .file(
                "sys/fs/cgroup/memory/kube/pod1/memory.usage_in_bytes",
                "1073741824\n",
            );
        let path = f
            .root
            .join("sys/fs/cgroup/memory/kube/memory.limit_in_bytes");
        assert_eq!(
            f.avail(),
            Some(MemoryLimit {
                bytes: 6 * GIB,
                source: LimitSource::CgroupV1 { path }
            })
        );

        // No limit anywhere: MemAvailable binds.
        f.file(
            "sys/fs/cgroup/memory/kube/memory.limit_in_bytes",
            "9223372036854771712\n",
        );
        assert_eq!(f.avail().unwrap().source, LimitSource::MemAvailable);
    }

    #[test]
    fn cgroup_v1_combined_controllers() {
        let f = Fake::new("v1-comb");
        f.file("proc/self/cgroup", "3:cpu,memory:/j\n")
            .file(
                "sys/fs/cgroup/memory/j/memory.limit_in_bytes",
                "1073741824\n",
            )
            .file("sys/fs/cgroup/memory/j/memory.usage_in_bytes", "0\n");
        assert_eq!(f.avail().unwrap().bytes, GIB);
    }

    #[test]
    fn climbing_cgroup_path_reads_only_the_mount_root() {
        let f = Fake::new("climb");
        f.file("proc/self/cgroup", "0::/../../etc\n")
            .file("sys/fs/cgroup/memory.max", "1073741824\n")
            .file("sys/fs/cgroup/memory.current", "0\n")
            .file("sys/fs/cgroup/etc/memory.max", "1\n")
            .file("sys/fs/cgroup/etc/memory.current", "0\n");
        assert_eq!(f.avail().unwrap().bytes, GIB);
    }

    #[test]
    fn malformed_files_are_skipped() {
        let f = Fake::new("malformed");
        f.file("proc/meminfo", "MemAvailable: lots kB\n")
            .file(
                "proc/self/limits",
                "Max address space         -5      unlimited  bytes\nMax data size\n",
            )
            .file("proc/self/status", "VmSize: ??? kB\n")
            .file("proc/self/cgroup", "0::/a\n4:memory:/a\ngarbage\n")
            .file("sys/fs/cgroup/a/memory.max", "12ab\n")
            .file("sys/fs/cgroup/a/memory.current", "0\n")
            .file("sys/fs/cgroup/memory.max", "1073741824\n") // no memory.current
            .file("sys/fs/cgroup/memory/a/memory.limit_in_bytes", "\n")
            .file("sys/fs/cgroup/memory/a/memory.usage_in_bytes", "0\n");
        assert_eq!(f.avail(), None);
        // A good file beside the bad ones still counts.
        f.file("sys/fs/cgroup/a/memory.max", "2147483648\n");
        assert_eq!(f.avail().unwrap().bytes, 2 * GIB);
    }

    #[test]
    fn headroom_saturates_at_zero() {
        let f = Fake::new("saturate");
        f.meminfo(16 << 20)
            .limits("1000000", "unlimited")
            .status(5_000_000, 10);
        assert_eq!(
            f.avail(),
            Some(MemoryLimit {
                bytes: 0,
                source: LimitSource::AddressSpace
            })
        );

        let g = Fake::new("saturate-cg");
        g.file("proc/self/cgroup", "0::/\n")
            .file("sys/fs/cgroup/memory.max", "100\n")
            .file("sys/fs/cgroup/memory.current", "200\n");
        assert_eq!(g.avail().unwrap().bytes, 0);
        assert!(check_against("--res 1x1", 0, None, g.avail()).is_err());
    }

    #[test]
    fn sources_display_as_phrases() {
        let p = PathBuf::from("/sys/fs/cgroup/a/memory.max");
        assert_eq!(
            LimitSource::CgroupV2 { path: p }.to_string(),
            "the cgroup's memory.max (/sys/fs/cgroup/a/memory.max) less memory.current"
        );
        assert_eq!(
            LimitSource::AddressSpace.to_string(),
            "the address-space limit (ulimit -v)"
        );
        assert_eq!(
            LimitSource::DataSegment.to_string(),
            "the data-segment limit (ulimit -d)"
        );
        assert_eq!(
            LimitSource::MemAvailable.to_string(),
            "MemAvailable in /proc/meminfo"
        );
    }

    #[test]
    fn check_names_job_limit_and_remedy() {
        let machine = MemoryLimit {
            bytes: 4_090_000_000,
            source: LimitSource::AddressSpace,
        };
        let e = check_against(
            "--res 20000x20000",
            24 * 20000 * 20000,
            None,
            Some(machine.clone()),
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "--res 20000x20000: the job would need about 8.97 GiB of memory; 3.81 GiB is left \
             under the address-space limit (ulimit -v). Lower --res or raise ulimit -v."
        );
        assert_eq!(e.need(), 24 * 20000 * 20000 + BASE_BYTES);
        assert_eq!(e.limit(), Some(&machine));
        assert_eq!(e.what(), "--res 20000x20000");

        // The tighter of --max-memory and the machine binds.
        let e =
            check_against("--m 4096", 3 * GIB, Some(2 * GIB), Some(machine.clone())).unwrap_err();
        assert_eq!(e.limit().unwrap().source, LimitSource::MaxMemoryFlag);
        assert!(
            e.to_string()
                .ends_with("--max-memory allows 2.00 GiB. Lower --m or raise --max-memory."),
            "{e}"
        );
        let e = check_against("--m 4096", 4 * GIB, Some(5 * GIB), Some(machine)).unwrap_err();
        assert_eq!(e.limit().unwrap().source, LimitSource::AddressSpace);

        let mem = MemoryLimit {
            bytes: GIB,
            source: LimitSource::MemAvailable,
        };
        let e = check_against("--res 9000x9000", 2 * GIB, None, Some(mem)).unwrap_err();
        assert!(
            e.to_string().contains(
                "1.00 GiB is available (MemAvailable in /proc/meminfo). Lower --res or free memory"
            ),
            "{e}"
        );

        // BASE_BYTES counts; nothing known allows anything.
        assert!(check_against("--res 8x8", GIB - BASE_BYTES, Some(GIB), None).is_ok());
        assert!(check_against("--res 8x8", GIB - BASE_BYTES + 1, Some(GIB), None).is_err());
        assert!(check_against("--res 8x8", u64::MAX, None, None).is_ok());
    }

    #[test]
    fn sizes_parse_and_estimates_refuse() {
        assert_eq!(parse_size("4096"), Ok(4096));
        assert_eq!(parse_size("2K"), Ok(2048));
        assert_eq!(parse_size("1.5G"), Ok(3 << 29));
        assert_eq!(parse_size("8GiB"), Ok(8 << 30));
        assert!(parse_size("-1G").is_err() && parse_size("3X").is_err() && parse_size("").is_err());
        assert!(check("--res 8x8", 1000, Some(1 << 30)).is_ok());
        let e = check("--res 9999x9999", 24 * 9999 * 9999, Some(1 << 30)).unwrap_err();
        assert!(
            e.to_string().contains("--res 9999x9999") && e.to_string().contains("2.27 GiB"),
            "{e}"
        );
    }

    #[test]
    fn held_bytes_count_against_the_cap_only() {
        // 0.25 GiB more on top of 2 GiB held: over a 2 GiB cap, though the machine has room.
        let e = check_more("--res 8x8", GIB / 4, 2 * GIB, Some(2 * GIB)).unwrap_err();
        assert_eq!(e.limit().unwrap().source, LimitSource::MaxMemoryFlag);
        assert_eq!(e.need(), 2 * GIB + GIB / 4 + BASE_BYTES);
        assert!(check_more("--res 8x8", GIB / 4, GIB, Some(2 * GIB)).is_ok());
        // Without a cap, only the machine's headroom counts (it excludes what is held).
        assert!(check_more("--res 8x8", 1 << 20, u64::MAX / 2, None).is_ok());
    }

    #[test]
    fn allocations_fill_or_fail_with_a_message() {
        let v = try_alloc_vec(1000, 7u32, "the film").unwrap();
        assert!(v.len() == 1000 && v.iter().all(|&x| x == 7));
        let v: Vec<u64> = try_with_capacity(1000, "the tiles").unwrap();
        assert!(v.is_empty() && v.capacity() >= 1000);
        assert!(try_alloc_vec(0, String::new(), "nothing")
            .unwrap()
            .is_empty());

        // Past isize::MAX bytes: refused whatever the machine.
        let e = try_alloc_vec(usize::MAX / 8, 0u64, "--res 99999999x99999999").unwrap_err();
        let bytes = (usize::MAX / 8) as u64 * 8;
        assert_eq!(e.need(), bytes);
        assert!(
            e.to_string().starts_with(&format!(
                "--res 99999999x99999999: could not allocate {bytes} bytes"
            )),
            "{e}"
        );
        assert!(try_with_capacity::<[u8; 16]>(usize::MAX / 8, "the table").is_err());

        let shown = MemoryError {
            what: "the film".into(),
            need: 2 * GIB,
            failure: Failure::Allocation(Some(MemoryLimit {
                bytes: GIB,
                source: LimitSource::DataSegment,
            })),
        };
        assert_eq!(
            shown.to_string(),
            "the film: could not allocate 2147483648 bytes (2.00 GiB); 1.00 GiB is left under the \
             data-segment limit (ulimit -d). Make the job smaller or raise ulimit -d."
        );
    }

    /// Run with `--nocapture` to see this machine's limit; under `ulimit -v` it must bind.
    #[test]
    fn real_machine() {
        let a = available();
        println!("available() = {a:?}");
        if let Some(l) = &a {
            println!("  {}", l.phrase());
        }
        if !cfg!(target_os = "linux") {
            return;
        }
        let l = a.expect("Linux has /proc/meminfo");
        let mem = mem_available(Path::new("/")).expect("MemAvailable");
        assert!(l.bytes <= mem.bytes);
        let limits = fs::read_to_string("/proc/self/limits").unwrap();
        let soft_as = limits
            .lines()
            .find_map(|l| l.strip_prefix("Max address space"))
            .and_then(|r| r.split_whitespace().next()?.parse::<u64>().ok());
        if let Some(soft) = soft_as {
            assert!(l.bytes < soft);
            if soft < mem.bytes {
                assert_eq!(l.source, LimitSource::AddressSpace);
                // An allocation past the limit fails with a message rather than aborting.
                let e = try_alloc_vec(soft as usize, 0u8, "--res 99999x99999").unwrap_err();
                println!("  {e}");
                assert_eq!(e.limit().unwrap().source, LimitSource::AddressSpace);
                assert!(e.to_string().contains("ulimit -v"));
            }
        }
    }
}
