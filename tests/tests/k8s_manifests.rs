//! The Kubernetes manifests of `deploy/k8s`, checked offline: every file
//! against the Kubernetes API's schemas by `kubernetes-validate` (PyPI; it
//! bundles the schemas, so no cluster and no network; `deploy/setup.sh`
//! installs it), strictly, so a misspelt field fails as a wrong type does;
//! a broken manifest is refused, so the check can fail; and what no schema
//! says: the server's settings are keys the server knows (it refuses the
//! others at start), its probes are the health endpoints, its replicas share
//! one ReadWriteMany volume, and runners are Guaranteed on benchmark nodes.

use std::path::{Path, PathBuf};
use std::process::Command;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// The manifests: every `.yaml` file of `deploy/k8s`, sorted.
fn manifests() -> Vec<PathBuf> {
    let dir = workspace().join("deploy/k8s");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "yaml" || e == "yml"))
        .collect();
    files.sort();
    assert!(files.len() >= 4, "too few manifests in {}: {files:?}", dir.display());
    files
}

/// `kubernetes-validate --strict` on `files`: (valid, what it printed).
/// A warning fails too: an unknown kind (a misspelt `kind:`) is only a
/// warning to it ("Couldn't find schema"), with success.
fn validate(files: &[PathBuf]) -> (bool, String) {
    let out = Command::new("python3")
        .args(["-m", "kubernetes_validate", "--strict", "--quiet"])
        .args(files)
        .output()
        .unwrap_or_else(|e| panic!("kubernetes-validate: {e} (deploy/setup.sh installs it with pip)"));
    let output = String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    (out.status.success() && !output.contains("WARN"), output)
}

#[test]
fn every_manifest_validates_against_the_kubernetes_schemas() {
    let files = manifests();
    let (valid, output) = validate(&files);
    assert!(valid, "kubernetes-validate refused deploy/k8s:\n{output}");
}

#[test]
fn a_broken_manifest_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let server = std::fs::read_to_string(workspace().join("deploy/k8s/server.yaml")).unwrap();
    // The same file as it is passes here too, so what fails below is the breakage.
    let intact = dir.path().join("intact.yaml");
    std::fs::write(&intact, &server).unwrap();
    let (valid, output) = validate(std::slice::from_ref(&intact));
    assert!(valid, "{output}");
    for (name, from, to) in [
        ("wrong-type.yaml", "replicas: 2", "replicas: two"),
        ("unknown-field.yaml", "readinessProbe:", "readynessProbe:"),
        ("wrong-kind.yaml", "kind: Deployment", "kind: Deploymant"),
    ] {
        assert!(server.contains(from), "server.yaml no longer has {from:?}: change this test");
        let file = dir.path().join(name);
        std::fs::write(&file, server.replacen(from, to, 1)).unwrap();
        let (valid, output) = validate(std::slice::from_ref(&file));
        assert!(!valid, "{name} ({from:?} made {to:?}) was accepted:\n{output}");
        assert!(output.contains(name), "the refusal names the file:\n{output}");
    }
}

/// Every document of every manifest, as JSON (PyYAML: kubernetes-validate's own dependency).
fn documents() -> Vec<serde_json::Value> {
    let out = Command::new("python3")
        .args(["-c", "import sys, json, yaml; print(json.dumps([d for f in sys.argv[1:] for d in yaml.safe_load_all(open(f)) if d]))"])
        .args(manifests())
        .output()
        .expect("python3 runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

fn find<'a>(docs: &'a [serde_json::Value], kind: &str, name: &str) -> &'a serde_json::Value {
    docs.iter()
        .find(|d| d["kind"] == kind && d["metadata"]["name"] == name)
        .unwrap_or_else(|| panic!("no {kind} {name} in deploy/k8s"))
}

/// The server's settings: the fields of `Config` in server/src/config.rs.
fn server_settings() -> Vec<String> {
    let source = std::fs::read_to_string(workspace().join("server/src/config.rs")).unwrap();
    let body = source.split("pub struct Config {").nth(1).and_then(|rest| rest.split("\n}").next()).unwrap();
    let fields: Vec<String> = body
        .lines()
        .filter_map(|l| l.trim().strip_prefix("pub ")?.split_once(':').map(|(name, _)| name.trim().to_string()))
        .collect();
    assert!(fields.contains(&"database_url".to_string()), "{fields:?}");
    fields
}

#[test]
fn the_manifests_configure_what_the_programs_read() {
    let docs = documents();
    // The server refuses an FBKSD_SERVER_* variable it does not know.
    let settings = server_settings();
    let config = &find(&docs, "ConfigMap", "fbksd-server")["data"];
    for key in config.as_object().unwrap().keys() {
        if let Some(setting) = key.strip_prefix("FBKSD_SERVER_") {
            assert!(settings.contains(&setting.to_lowercase()), "the server has no setting {key}: {settings:?}");
        }
    }
    assert_eq!(config["FBKSD_SERVER_DATA_DIR"], "/var/lib/fbksd");

    // Two server instances, probed at the health endpoints, on one shared volume.
    let server = find(&docs, "Deployment", "fbksd-server");
    assert_eq!(server["spec"]["replicas"], 2);
    let pod = &server["spec"]["template"]["spec"];
    let container = &pod["containers"][0];
    assert_eq!(container["livenessProbe"]["httpGet"]["path"], "/healthz");
    assert_eq!(container["readinessProbe"]["httpGet"]["path"], "/readyz");
    let data = pod["volumes"].as_array().unwrap().iter().find(|v| v["name"] == "data").unwrap();
    let claim = find(&docs, "PersistentVolumeClaim", data["persistentVolumeClaim"]["claimName"].as_str().unwrap());
    assert_eq!(claim["spec"]["accessModes"], serde_json::json!(["ReadWriteMany"]));
    let mounted = container["volumeMounts"].as_array().unwrap().iter().find(|m| m["name"] == "data").unwrap();
    assert_eq!(mounted["mountPath"], config["FBKSD_SERVER_DATA_DIR"]);

    // Runners: benchmark nodes only; Guaranteed QoS in whole CPUs (the
    // static CPU manager then gives them cores of their own); the node's
    // Docker engine; work and rendezvous directories at their node paths.
    let runner = &find(&docs, "Deployment", "fbksd-runner")["spec"]["template"]["spec"];
    assert_eq!(runner["nodeSelector"]["fbksd/benchmark"], "true");
    for container in runner["containers"].as_array().unwrap() {
        let resources = &container["resources"];
        assert_eq!(resources["requests"], resources["limits"], "requests == limits: {resources}");
        let cpu = resources["limits"]["cpu"].as_str().unwrap();
        assert!(cpu.parse::<u32>().is_ok_and(|n| n > 0), "whole CPUs, not {cpu:?}");
        assert!(resources["limits"]["memory"].is_string(), "{resources}");
    }
    let volumes = runner["volumes"].as_array().unwrap();
    let host_path = |name: &str| {
        volumes.iter().find(|v| v["name"] == name).unwrap_or_else(|| panic!("no volume {name}"))["hostPath"]["path"]
            .clone()
    };
    assert_eq!(host_path("docker"), "/var/run/docker.sock");
    let mounts = runner["containers"][0]["volumeMounts"].as_array().unwrap();
    for name in ["work", "rendezvous"] {
        let mount = mounts.iter().find(|m| m["name"] == name).unwrap();
        assert_eq!(mount["mountPath"], host_path(name), "{name} is mounted at its path on the node");
    }
    let env = runner["containers"][0]["env"].as_array().unwrap();
    let value = |key: &str| env.iter().find(|e| e["name"] == key).map(|e| e["value"].clone());
    assert_eq!(value("FBKSD_CI_WORK_ROOT"), Some(host_path("work")));
    assert_eq!(value("FBKSD_RUNTIME_DIR"), Some(host_path("rendezvous")));
}
