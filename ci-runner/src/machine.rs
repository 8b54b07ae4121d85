//! What a result needs to say about the machine it was measured on.

use serde::Serialize;

/// The CPU a runner measures on.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Machine {
    /// `model name` from /proc/cpuinfo.
    pub cpu_model: String,
    /// Logical cores the containers are pinned to.
    pub cores: usize,
    /// The pinned cores, as Docker's cpuset (`0-3`).
    pub cpuset: String,
    /// Logical cores of the machine.
    pub machine_cores: usize,
    /// Kernel release.
    pub kernel: String,
}

impl Machine {
    /// This machine, with containers pinned to `cpuset` (all cores when `None`).
    pub fn probe(cpuset: Option<&str>) -> Machine {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let cpu_model = cpuinfo
            .lines()
            .find_map(|l| l.strip_prefix("model name").and_then(|r| r.split_once(':')).map(|(_, v)| v.trim()))
            .unwrap_or("unknown")
            .to_string();
        let machine_cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let cpuset = cpuset.map_or_else(|| format!("0-{}", machine_cores - 1), str::to_string);
        Machine {
            cpu_model,
            cores: count_cpus(&cpuset).unwrap_or(machine_cores),
            cpuset,
            machine_cores,
            kernel: std::fs::read_to_string("/proc/sys/kernel/osrelease").unwrap_or_default().trim().to_string(),
        }
    }
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
    let mut cpus = Vec::new();
    for part in cpuset.split(',') {
        match part.split_once('-') {
            Some((a, b)) => cpus.extend(a.trim().parse::<usize>().ok()?..=b.trim().parse::<usize>().ok()?),
            None => cpus.push(part.trim().parse::<usize>().ok()?),
        }
    }
    if cpus.len() < 4 {
        return None;
    }
    let join = |c: &[usize]| c.iter().map(usize::to_string).collect::<Vec<_>>().join(",");
    let (renderer, technique) = cpus.split_at(cpus.len() / 2);
    Some(RoleCores { renderer: join(renderer), technique: join(technique) })
}

/// The number of cores a cpuset list names (`0-3,6` → 5); `None` when malformed.
pub fn count_cpus(cpuset: &str) -> Option<usize> {
    let mut n = 0;
    for part in cpuset.split(',') {
        n += match part.split_once('-') {
            Some((a, b)) => b.trim().parse::<usize>().ok()?.checked_sub(a.trim().parse::<usize>().ok()?)? + 1,
            None => {
                part.trim().parse::<usize>().ok()?;
                1
            }
        };
    }
    Some(n)
}

#[cfg(test)]
mod tests {
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
