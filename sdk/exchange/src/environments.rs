//! What each environment (the image a technique is built and run in) holds:
//! the packages, their versions, and the headers and modules a build names.
//! One list serves the site's `/environments` page, README, the refusal of
//! an unknown environment at push, and the hint a failed build gets
//! ([`Environment::explain_missing`]). `deploy/images/*/Dockerfile` install
//! these packages; a test in `ci-runner` checks every version against the
//! built images, so the list cannot drift from them.

use crate::technique::Environment;
use serde::Serialize;

/// Where a package comes from, which is also how its installed version is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(tag = "kind", content = "name", rename_all = "snake_case")]
pub enum Source {
    /// A Debian 12 package (`dpkg-query -W` gives its version).
    Debian(&'static str),
    /// A wheel pinned in `deploy/images/python/requirements.txt`.
    Wheel(&'static str),
    /// This repository (the FBKSD SDK itself).
    Fbksd,
}

/// One package of an environment.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Package {
    /// Name shown to users.
    pub name: &'static str,
    /// Installed version (upstream part of the Debian version, or the wheel's).
    pub version: &'static str,
    /// What it is for, in a few words.
    pub what: &'static str,
    /// Where it comes from.
    pub source: Source,
    /// Headers a build includes, as written in `#include` with the package's
    /// usual include directories (OpenEXR's, Eigen's, OpenCV's); an entry
    /// ending in `/` stands for every header under that directory.
    pub headers: &'static [&'static str],
    /// Python modules it provides.
    pub modules: &'static [&'static str],
    /// Other names it goes by in build files and errors (CMake package names, …).
    pub aliases: &'static [&'static str],
}

const CPP: &[Package] = &[
    Package {
        name: "g++",
        version: "12.2.0",
        what: "GCC's C++ compiler (C++17 by default), with OpenMP (libgomp)",
        source: Source::Debian("g++-12"),
        headers: &["omp.h"],
        modules: &[],
        aliases: &["OpenMP", "gcc"],
    },
    Package {
        name: "CMake",
        version: "3.25.1",
        what: "builds the repository's CMakeLists.txt (also files asking for CMake 2.8)",
        source: Source::Debian("cmake"),
        headers: &[],
        modules: &[],
        aliases: &["cmake"],
    },
    Package {
        name: "FBKSD C/C++ SDK",
        version: "2.x compatible",
        what: "find_package(fbksd), fbksd::client; the 2.x client, renderer and IQA headers",
        source: Source::Fbksd,
        headers: &["fbksd/"],
        modules: &[],
        aliases: &["fbksd"],
    },
    Package {
        name: "OpenEXR",
        version: "3.1.5",
        what: "EXR images; OpenEXR 2's names work too (/usr/include/OpenEXR holds Imath's headers, -lIlmImf, -lHalf)",
        source: Source::Debian("libopenexr-dev"),
        headers: &["OpenEXR/", "ImfRgbaFile.h", "ImfInputFile.h", "ImfOutputFile.h", "ImfArray.h", "ImfChannelList.h"],
        modules: &[],
        aliases: &["OpenEXR", "IlmImf", "IlmBase"],
    },
    Package {
        name: "Imath",
        version: "3.1.6",
        what: "half floats and small vector maths (OpenEXR's)",
        source: Source::Debian("libimath-dev"),
        headers: &["Imath/", "half.h", "ImathVec.h", "ImathBox.h", "ImathMatrix.h"],
        modules: &[],
        aliases: &["Imath", "Half"],
    },
    Package {
        name: "Eigen",
        version: "3.4.0",
        what: "dense and sparse linear algebra (headers in /usr/include/eigen3; find_package(Eigen3))",
        source: Source::Debian("libeigen3-dev"),
        headers: &["eigen3/", "Eigen/", "Eigen/Dense", "Eigen/Core", "Eigen/Sparse"],
        modules: &[],
        aliases: &["Eigen3", "Eigen"],
    },
    Package {
        name: "OpenCV",
        version: "4.6.0",
        what: "core, imgproc, imgcodecs and photo (its non-local means denoisers); find_package(OpenCV)",
        source: Source::Debian("libopencv-core-dev"),
        headers: &["opencv4/", "opencv2/core.hpp", "opencv2/imgproc.hpp", "opencv2/imgcodecs.hpp", "opencv2/photo.hpp"],
        modules: &[],
        aliases: &["OpenCV"],
    },
    Package {
        name: "FFTW",
        version: "3.3.10",
        what: "fast Fourier transforms (single, double and long double)",
        source: Source::Debian("libfftw3-dev"),
        headers: &["fftw3.h"],
        modules: &[],
        aliases: &["FFTW3", "fftw"],
    },
    Package {
        name: "Boost",
        version: "1.74.0",
        what: "the header libraries, filesystem and program_options",
        source: Source::Debian("libboost-dev"),
        headers: &["boost/"],
        modules: &[],
        aliases: &["Boost"],
    },
    Package {
        name: "oneTBB",
        version: "2021.8.0",
        what: "Intel Threading Building Blocks (parallel_for, task arenas)",
        source: Source::Debian("libtbb-dev"),
        headers: &["tbb/", "oneapi/tbb.h"],
        modules: &[],
        aliases: &["TBB"],
    },
];

const PYTHON: &[Package] = &[
    Package {
        name: "Python",
        version: "3.11.2",
        what: "CPython, Debian's",
        source: Source::Debian("python3"),
        headers: &[],
        modules: &[],
        aliases: &["python3"],
    },
    Package {
        name: "FBKSD Python SDK",
        version: "2.x compatible",
        what: "import fbksd: the client with numpy views of every tile",
        source: Source::Fbksd,
        headers: &[],
        modules: &["fbksd"],
        aliases: &[],
    },
    Package {
        name: "numpy",
        version: "2.4.6",
        what: "arrays",
        source: Source::Wheel("numpy"),
        headers: &[],
        modules: &["numpy"],
        aliases: &[],
    },
    Package {
        name: "SciPy",
        version: "1.17.1",
        what: "signal and image filters, sparse solvers, optimisation",
        source: Source::Wheel("scipy"),
        headers: &[],
        modules: &["scipy"],
        aliases: &[],
    },
    Package {
        name: "OpenEXR",
        version: "3.5.3",
        what: "EXR images from Python (import OpenEXR)",
        source: Source::Wheel("OpenEXR"),
        headers: &[],
        modules: &["OpenEXR", "Imath"],
        aliases: &[],
    },
    Package {
        name: "Intel Open Image Denoise",
        version: "2.5.1.0",
        what: "pyoidn: OIDN's neural denoiser on the CPU, with albedo and normal features",
        source: Source::Wheel("pyoidn"),
        headers: &[],
        modules: &["pyoidn"],
        aliases: &["oidn", "OpenImageDenoise"],
    },
];

/// What a build reported missing.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Missing {
    Header(String),
    Module(String),
    CMakePackage(String),
}

impl Environment {
    /// Every environment, in the order pages list them.
    pub const ALL: [Environment; 2] = [Environment::Cpp, Environment::Python];

    /// What is in it.
    pub fn packages(self) -> &'static [Package] {
        match self {
            Environment::Cpp => CPP,
            Environment::Python => PYTHON,
        }
    }

    /// The environment called `name` in `info.json`.
    pub fn named(name: &str) -> Option<Environment> {
        Environment::ALL.into_iter().find(|e| e.as_str() == name)
    }

    /// Its packages with their versions, comma-separated.
    pub fn contents(self) -> String {
        self.packages().iter().map(|p| format!("{} {}", p.name, p.version)).collect::<Vec<_>>().join(", ")
    }

    /// One line: the base system and the packages.
    pub fn summary(self) -> String {
        format!("Debian 12; {}", self.contents())
    }

    /// `"cpp" (…), "python" (…)`, for messages that list the choices.
    pub fn choices() -> String {
        let describe = |e: Environment| match e {
            Environment::Cpp => "\"cpp\" (CMake, gcc and C++ libraries)",
            Environment::Python => "\"python\" (Python 3, numpy, scipy, pyoidn)",
        };
        Environment::ALL.iter().map(|e| describe(*e)).collect::<Vec<_>>().join(" or ")
    }

    /// A hint for a build or run log that failed on something missing (a
    /// header, a Python module, a CMake package): names this environment and
    /// what it has, and suggests the environment that has the missing thing
    /// or the closest name this one has. None when the log shows no such failure.
    pub fn explain_missing(self, log: &str) -> Option<String> {
        let missing = find_missing(log)?;
        let (what, name) = match &missing {
            Missing::Header(n) => ("header", n),
            Missing::Module(n) => ("Python module", n),
            Missing::CMakePackage(n) => ("CMake package", n),
        };
        let mut hint = format!("{what} `{name}` is not in the {} environment.", self.as_str());
        let elsewhere = Environment::ALL
            .iter()
            .filter(|e| **e != self)
            .find_map(|e| e.packages().iter().find(|p| provides(p, &missing)).map(|p| (*e, p)));
        if let Some((other, package)) = elsewhere {
            hint += &format!(
                " The {} environment has {} {}: set \"environment\": \"{}\" in info.json to build there.",
                other.as_str(),
                package.name,
                package.version,
                other.as_str()
            );
        } else if let Some(closest) = self.closest(&missing) {
            hint += &format!(" Did you mean `{closest}`?");
        }
        hint += &format!(" It has: {} (see /environments on the service).", self.contents());
        Some(hint)
    }

    /// The name this environment has that is nearest to `missing`, if near enough to be a typo.
    fn closest(self, missing: &Missing) -> Option<&'static str> {
        let (name, candidates): (&str, Vec<&'static str>) = match missing {
            Missing::Header(n) => (n, self.packages().iter().flat_map(|p| p.headers.iter().copied()).collect()),
            Missing::Module(n) => (n, self.packages().iter().flat_map(|p| p.modules.iter().copied()).collect()),
            Missing::CMakePackage(n) => (n, self.packages().iter().flat_map(|p| p.aliases.iter().copied()).collect()),
        };
        let lower = name.to_ascii_lowercase();
        candidates
            .into_iter()
            .filter(|c| !c.ends_with('/'))
            .map(|c| (strsim::levenshtein(&lower, &c.to_ascii_lowercase()), c))
            .filter(|(d, _)| *d <= (name.len() / 4).max(2))
            .min()
            .map(|(_, c)| c)
    }
}

/// Whether `package` provides what was missing.
fn provides(package: &Package, missing: &Missing) -> bool {
    let alias = |n: &str| package.aliases.iter().any(|a| n.to_ascii_lowercase().contains(&a.to_ascii_lowercase()));
    match missing {
        Missing::Header(n) => {
            package.headers.iter().any(|h| if h.ends_with('/') { n.starts_with(h) } else { n == h }) || alias(n)
        }
        Missing::Module(n) => {
            let top = n.split('.').next().unwrap_or(n);
            package.modules.contains(&top) || alias(n)
        }
        Missing::CMakePackage(n) => alias(n) || package.name.eq_ignore_ascii_case(n),
    }
}

/// The first thing the log says is missing.
fn find_missing(log: &str) -> Option<Missing> {
    log.lines().find_map(|line| {
        // gcc: `main.cpp:3:10: fatal error: Foo/bar.h: No such file or directory`
        if let Some(rest) = line.split("fatal error: ").nth(1) {
            if let Some(name) = rest.strip_suffix(": No such file or directory") {
                return Some(Missing::Header(name.trim().to_string()));
            }
        }
        // Python: `ModuleNotFoundError: No module named 'torch'`
        if let Some(rest) = line.split("No module named '").nth(1) {
            return rest.split('\'').next().map(|n| Missing::Module(n.to_string()));
        }
        // CMake: `Could not find a package configuration file provided by "OpenImageDenoise"`
        if let Some(rest) = line.split("provided by \"").nth(1) {
            return rest.split('"').next().map(|n| Missing::CMakePackage(n.to_string()));
        }
        None
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_header_names_the_environment_and_what_it_has() {
        let log = "main.cpp:2:10: fatal error: tiffio.h: No such file or directory\ncompilation terminated.";
        let hint = Environment::Cpp.explain_missing(log).unwrap();
        assert!(hint.starts_with("header `tiffio.h` is not in the cpp environment."), "{hint}");
        assert!(hint.contains("OpenEXR 3.1.5") && hint.contains("/environments"), "{hint}");
    }

    #[test]
    fn a_typo_gets_the_closest_header() {
        let log = "x.cpp:1:10: fatal error: Eigen/dense: No such file or directory";
        assert!(Environment::Cpp.explain_missing(log).unwrap().contains("Did you mean `Eigen/Dense`?"));
    }

    #[test]
    fn what_another_environment_has_points_there() {
        let log = "denoise.cpp:4:10: fatal error: OpenImageDenoise/oidn.hpp: No such file or directory";
        let hint = Environment::Cpp.explain_missing(log).unwrap();
        assert!(hint.contains("The python environment has Intel Open Image Denoise 2.5.1.0"), "{hint}");
        let log = "ModuleNotFoundError: No module named 'cv2'";
        let hint = Environment::Python.explain_missing(log).unwrap();
        assert!(hint.starts_with("Python module `cv2` is not in the python environment."), "{hint}");
        let log = "  Could not find a package configuration file provided by \"Eigen3\" with any";
        let hint = Environment::Python.explain_missing(log).unwrap();
        assert!(hint.contains("The cpp environment has Eigen 3.4.0"), "{hint}");
    }

    #[test]
    fn a_log_without_a_missing_file_gets_no_hint() {
        assert_eq!(Environment::Cpp.explain_missing("main.cpp:3:5: error: expected ';'"), None);
    }
}
