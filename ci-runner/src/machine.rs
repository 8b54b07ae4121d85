//! What a result needs to say about the machine it was measured on, and
//! the runner class its times are compared within.
//!
//! A class is what decides how much CPU time a technique's work costs: the
//! CPU model, its vector ISA level, the cores a run may use, the memory
//! and the CPU quota of its containers, if any. Two runners of one class
//! give one technique the same cost within the noise; runners of different
//! classes are not compared. The quota is part of the class because it
//! moves costs without moving the calibration: under half a core the
//! costs rose by a median 10–13 % while the calibration moved by 2 %
//! (`deploy/bench-runner-classes.sh`, see ci-runner/README.md), so the
//! server's drift check could not tell a quota'd runner from its class.

use crate::calibration::Calibration;
use serde::Serialize;

/// The CPU a runner measures on.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Machine {
    /// The runner class: the fields that set the cost of work, in one
    /// line (times are compared only within one).
    pub class: String,
    /// `model name` from /proc/cpuinfo.
    pub cpu_model: String,
    /// The x86-64 micro-architecture level the CPU's flags reach
    /// (`x86-64-v4` has AVX-512), or the architecture elsewhere.
    pub isa: String,
    /// Logical cores the containers are pinned to.
    pub cores: usize,
    /// The pinned cores, as Docker's cpuset (`0-3`).
    pub cpuset: String,
    /// Logical cores of the machine.
    pub machine_cores: usize,
    /// The machine's memory, in GiB (rounded).
    pub memory_gib: u64,
    /// The CPU quota of every container, in cores, when one is set.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cpu_quota: Option<f64>,
    /// Kernel release.
    pub kernel: String,
}

impl Machine {
    /// This machine, with containers pinned to `cpuset` (all cores when
    /// `None`) under a quota of `cpu_quota` cores (none when `None`).
    pub fn probe(cpuset: Option<&str>, cpu_quota: Option<f64>) -> Machine {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let field = |name: &str| {
            cpuinfo.lines().find_map(|l| {
                let (key, value) = l.split_once(':')?;
                (key.trim() == name).then(|| value.trim().to_string())
            })
        };
        let cpu_model = field("model name").unwrap_or_else(|| "unknown".into());
        let isa = isa_level(std::env::consts::ARCH, &field("flags").unwrap_or_default());
        let memory_gib = std::fs::read_to_string("/proc/meminfo")
            .ok()
            .and_then(|m| {
                let kib = m.lines().find_map(|l| l.strip_prefix("MemTotal:"))?.trim().trim_end_matches("kB").trim();
                kib.parse::<u64>().ok()
            })
            .map_or(0, |kib| (kib as f64 / (1024.0 * 1024.0)).round() as u64);
        let machine_cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let cpuset = cpuset.map_or_else(|| format!("0-{}", machine_cores - 1), str::to_string);
        let cores = count_cpus(&cpuset).unwrap_or(machine_cores);
        Machine {
            class: class(&cpu_model, &isa, cores, memory_gib, cpu_quota),
            cpu_model,
            isa,
            cores,
            cpuset,
            machine_cores,
            memory_gib,
            cpu_quota,
            kernel: std::fs::read_to_string("/proc/sys/kernel/osrelease").unwrap_or_default().trim().to_string(),
        }
    }

    /// What a result (and the runner's registration) stores of the
    /// machine: its fields and the latest calibration.
    pub fn record(&self, calibration: &Calibration) -> serde_json::Value {
        let mut record = serde_json::to_value(self).unwrap_or_default();
        record["calibration"] = serde_json::to_value(calibration).unwrap_or_default();
        record
    }
}

/// The class's one-line name (`… · 2 cores · 24 GiB`, then
/// `· quota 0.5 cores` under a quota).
pub fn class(cpu_model: &str, isa: &str, cores: usize, memory_gib: u64, cpu_quota: Option<f64>) -> String {
    let cores = if cores == 1 { "1 core".to_string() } else { format!("{cores} cores") };
    let quota = cpu_quota.map_or_else(String::new, |q| format!(" · quota {q} cores"));
    format!("{cpu_model} · {isa} · {cores} · {memory_gib} GiB{quota}")
}

/// The x86-64 level (`x86-64-v1` … `v4`) that `flags` (/proc/cpuinfo) reach
/// on x86_64; the architecture's name elsewhere.
pub fn isa_level(arch: &str, flags: &str) -> String {
    if arch != "x86_64" {
        return arch.to_string();
    }
    let has: std::collections::BTreeSet<&str> = flags.split_whitespace().collect();
    let all = |needed: &[&str]| needed.iter().all(|f| has.contains(f));
    let v2 = all(&["cx16", "lahf_lm", "popcnt", "sse4_1", "sse4_2", "ssse3"]);
    let v3 = v2 && all(&["avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe", "xsave"]);
    let v4 = v3 && all(&["avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl"]);
    let level = [v2, v3, v4].iter().take_while(|&&reached| reached).count() + 1;
    format!("x86-64-v{level}")
}

/// Disjoint cores for the renderer and the technique of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct RoleCores {
    /// The renderer's cpuset (the first half).
    pub renderer: String,
    /// The technique's cpuset (the second half).
    pub technique: String,
}

/// Splits a cpuset of four cores or more into two disjoint halves; `None`
/// for fewer cores (both then share them) or a malformed list.
pub fn split_cpus(cpuset: &str) -> Option<RoleCores> {
    let cpus = cpus_of(cpuset)?;
    if cpus.len() < 4 {
        return None;
    }
    let join = |c: &[usize]| c.iter().map(usize::to_string).collect::<Vec<_>>().join(",");
    let (renderer, technique) = cpus.split_at(cpus.len() / 2);
    Some(RoleCores { renderer: join(renderer), technique: join(technique) })
}

/// The number of cores a cpuset list names (`0-3,6` → 5); `None` when malformed.
pub fn count_cpus(cpuset: &str) -> Option<usize> {
    cpus_of(cpuset).map(|cpus| cpus.len())
}

/// The cores a cpuset list names (`0-3,6` → 0, 1, 2, 3, 6); `None` when malformed.
pub fn cpus_of(cpuset: &str) -> Option<Vec<usize>> {
    let mut cpus = Vec::new();
    for part in cpuset.split(',') {
        match part.split_once('-') {
            Some((a, b)) => {
                let (a, b) = (a.trim().parse::<usize>().ok()?, b.trim().parse::<usize>().ok()?);
                if b < a {
                    return None;
                }
                cpus.extend(a..=b);
            }
            None => cpus.push(part.trim().parse::<usize>().ok()?),
        }
    }
    Some(cpus)
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_isa_level_is_the_highest_whose_flags_are_all_there() {
        let v2 = "fpu cx16 lahf_lm popcnt sse4_1 sse4_2 ssse3";
        let v3 = format!("{v2} avx avx2 bmi1 bmi2 f16c fma abm movbe xsave");
        let v4 = format!("{v3} avx512f avx512bw avx512cd avx512dq avx512vl");
        assert_eq!(super::isa_level("x86_64", "fpu sse2"), "x86-64-v1");
        assert_eq!(super::isa_level("x86_64", v2), "x86-64-v2");
        assert_eq!(super::isa_level("x86_64", &v3), "x86-64-v3");
        assert_eq!(super::isa_level("x86_64", &v4), "x86-64-v4");
        // AVX-512 without AVX2's companions is still v2.
        assert_eq!(
            super::isa_level("x86_64", &format!("{v2} avx512f avx512bw avx512cd avx512dq avx512vl")),
            "x86-64-v2"
        );
        assert_eq!(super::isa_level("aarch64", "fp asimd"), "aarch64");
    }

    #[test]
    fn this_machine_has_a_class_naming_its_cpu_isa_cores_and_memory() {
        let machine = super::Machine::probe(Some("0"), Some(0.5));
        assert_eq!(machine.cores, 1);
        assert!(machine.memory_gib > 0, "{machine:?}");
        assert_eq!(machine.class, super::class(&machine.cpu_model, &machine.isa, 1, machine.memory_gib, Some(0.5)));
        assert!(machine.class.contains(" · 1 core · "), "{}", machine.class);
        // A quota makes another class: its costs differ from the unquota'd runner's.
        let unquotad = super::Machine::probe(Some("0"), None).class;
        assert_eq!(machine.class, format!("{unquotad} · quota 0.5 cores"));
        assert_eq!(machine.cpu_quota, Some(0.5));
    }

    #[test]
    fn cpusets_are_counted() {
        assert_eq!(super::count_cpus("0-3,6"), Some(5));
        assert_eq!(super::count_cpus("1"), Some(1));
        assert_eq!(super::count_cpus("3-1"), None);
        assert_eq!(super::count_cpus("a"), None);
    }

    #[test]
    fn four_cores_or_more_are_split_between_the_roles() {
        assert_eq!(super::split_cpus("0-1"), None);
        assert_eq!(super::split_cpus("0-2"), None);
        let split = super::split_cpus("0-3").unwrap();
        assert_eq!((split.renderer.as_str(), split.technique.as_str()), ("0,1", "2,3"));
        let split = super::split_cpus("2,4-8").unwrap();
        assert_eq!((split.renderer.as_str(), split.technique.as_str()), ("2,4,5", "6,7,8"));
    }
}
