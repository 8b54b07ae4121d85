//! Faults: a runner killed mid-job, a runner stopped mid-job, the server
//! restarted mid-job, Docker unavailable, a runner kept beside a server
//! started afresh. In each, no job and no result is lost, and no container
//! is left behind.

mod common;

use common::*;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// The Python box filter, slowed down so that a fault can strike mid-run.
fn slow_box_filter(seconds: u32) -> tempfile::TempDir {
    let repo = technique_repository("box-filter-python");
    let script = repo.path().join("box_filter.py");
    let text = std::fs::read_to_string(&script).unwrap();
    let slowed = text.replace(
        "def main() -> None:\n",
        &format!("def main() -> None:\n    import time\n    time.sleep({seconds})\n"),
    );
    assert_ne!(text, slowed);
    std::fs::write(&script, slowed).unwrap();
    commit_all(repo.path(), "slow");
    repo
}

async fn start_benchmark(server: &TestServer, user: &TestUser, name: &str, repo: &std::path::Path) -> String {
    server.create_project(user, name, "private").await;
    let (pushed, output) = push(repo, &server.clone_url(name, &user.token), &["FBKSD_RUN"]);
    assert!(pushed, "{output}");
    newest_job(server, user, name, "benchmark").await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_runner_killed_mid_job_loses_its_lease_and_another_completes_the_job() {
    images();
    references(&["experimental/fireflies"]);
    let server = spawn_with(Db::Sqlite, |c| c.lease_seconds = 3).await;
    let ada = server.user("ada@example.org").await;
    let work = tempfile::tempdir().unwrap();
    let repo = slow_box_filter(4);
    let id = start_benchmark(&server, &ada, "slow-filter", repo.path()).await;

    let mut first = RunnerProcess::start(&server.url, &work.path().join("first"), &RunnerOptions::default());
    first.wait_for_output("build succeeded", Duration::from_secs(300));
    wait_for_running_container(&id, Duration::from_secs(120));
    let first_id = first.id().unwrap();
    first.kill();

    let second = RunnerProcess::start(&server.url, &work.path().join("second"), &RunnerOptions::default());
    let job = finished_job(&server, &ada, &id, Duration::from_secs(300)).await;
    let log = log_text(&server, &ada, &id).await;
    assert_eq!(job["state"], "succeeded", "{job}\n{log}\n{}", second.output());
    assert_eq!(job["attempts"], 2, "{job}");
    assert_eq!(job["runner_id"].as_str(), second.id().as_deref(), "{job}");
    assert!(job["result_id"].is_string(), "{job}");

    // The killed runner, started again, removes what it left behind.
    let again = RunnerProcess::start(&server.url, &work.path().join("first"), &RunnerOptions::default());
    again.wait_for_output("ready", Duration::from_secs(60));
    assert_eq!(again.id().as_deref(), Some(first_id.as_str()));
    assert_eq!(containers_labelled("org.fbksd.ci.runner", &first_id), Vec::<String>::new());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_runner_stopped_mid_job_starts_nothing_more_and_leaves_no_container() {
    images();
    references(&["experimental/fireflies"]);
    let server = spawn(Db::Sqlite).await;
    let ada = server.user("ada@example.org").await;
    let work = tempfile::tempdir().unwrap();
    let repo = slow_box_filter(2);
    let id = start_benchmark(&server, &ada, "stopped-filter", repo.path()).await;
    // Two budgets of three seeds: once its containers are gone, the
    // benchmark's thread would go on to the next run.
    let options = RunnerOptions { spp: "1,4", ..RunnerOptions::default() };
    let mut runner = RunnerProcess::start(&server.url, &work.path().join("runner"), &options);
    runner.wait_for_output("build succeeded", Duration::from_secs(300));
    wait_for_running_container(&id, Duration::from_secs(120));
    let runner_id = runner.id().unwrap();

    let status = runner.interrupt(Duration::from_secs(120));
    let output = runner.output();
    assert!(status.success(), "{status}\n{output}");
    assert!(output.contains("runner stopped"), "{output}");
    // Nothing of the job is left, running or exited, once the runner has gone.
    assert_eq!(containers_labelled("org.fbksd.ci.runner", &runner_id), Vec::<String>::new(), "{output}");
    assert_eq!(containers_labelled("org.fbksd.ci.job", &id), Vec::<String>::new(), "{output}");
}

/// The real `fbksd-server` binary, as a process (killed when dropped).
struct ServerProcess(Child);

impl ServerProcess {
    fn kill(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Drop for ServerProcess {
    fn drop(&mut self) {
        self.kill();
    }
}

fn server_process(port: u16, data: &std::path::Path) -> ServerProcess {
    let child = Command::new(bin_dir().join("fbksd-server"))
        .env("FBKSD_SERVER_BIND", format!("127.0.0.1:{port}"))
        .env("FBKSD_SERVER_DATA_DIR", data)
        .env("FBKSD_SERVER_PUBLIC_URL", format!("http://127.0.0.1:{port}"))
        .env("FBKSD_SERVER_RUNNER_REGISTRATION_TOKEN", REGISTRATION_TOKEN)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(data.with_extension("log")).unwrap())
        .spawn()
        .expect("fbksd-server starts");
    ServerProcess(child)
}

async fn wait_until_up(url: &str) {
    for _ in 0..200 {
        if reqwest::get(format!("{url}/results/")).await.is_ok() {
            return;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("the server at {url} did not come up");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_server_restarted_mid_job_loses_no_job_and_no_result() {
    images();
    references(&["experimental/fireflies"]);
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let data = tempfile::tempdir().unwrap();
    let data_dir = data.path().join("server");
    let mut server_child = server_process(port, &data_dir);
    let url = format!("http://127.0.0.1:{port}");
    wait_until_up(&url).await;
    let server = TestServer::at(url.clone(), data_dir.join("outbox"));
    let ada = server.user("ada@example.org").await;
    let repo = slow_box_filter(3);
    let id = start_benchmark(&server, &ada, "slow-filter", repo.path()).await;

    let options = RunnerOptions { spp: "1,2", ..Default::default() };
    let runner = RunnerProcess::start(&url, &data.path().join("runner"), &options);
    runner.wait_for_output("build succeeded", Duration::from_secs(300));
    server_child.kill();
    tokio::time::sleep(Duration::from_secs(3)).await;
    let _server_child = server_process(port, &data_dir);
    wait_until_up(&url).await;

    let job = finished_job(&server, &ada, &id, Duration::from_secs(300)).await;
    let log = log_text(&server, &ada, &id).await;
    assert_eq!(job["state"], "succeeded", "{job}\n{log}\n{}", runner.output());
    assert_eq!(job["attempts"], 1, "the job was not run again: {job}");
    for line in ["build succeeded", "fireflies at 1 spp", "fireflies at 2 spp", "private results: "] {
        assert!(log.contains(line), "{line:?} is missing from the log:\n{log}");
    }
    let result = job["result_id"].as_str().expect("a result set");
    let (status, set) =
        json_of(ada.api(reqwest::Method::GET, format!("{url}/api/v1/results/{result}")).send().await.unwrap()).await;
    assert_eq!(status, 200, "{set}");
    assert_eq!(set["runs"].as_array().unwrap().len(), 2, "{set}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_docker_a_runner_says_so_and_claims_nothing() {
    images();
    references(&["experimental/fireflies"]);
    let server = spawn(Db::Sqlite).await;
    let ada = server.user("ada@example.org").await;
    let repo = technique_repository("box-filter-python");
    let id = start_benchmark(&server, &ada, "box-filter-python", repo.path()).await;
    let work = tempfile::tempdir().unwrap();

    let options = RunnerOptions {
        env: vec![("DOCKER_HOST", "unix:///nonexistent/docker.sock".to_string())],
        ..Default::default()
    };
    let blind = RunnerProcess::start(&server.url, &work.path().join("blind"), &options);
    blind.wait_for_output("Docker is unavailable at unix:///nonexistent/docker.sock", Duration::from_secs(60));
    tokio::time::sleep(Duration::from_secs(2)).await;
    assert_eq!(job(&server, &ada, &id).await["state"], "queued", "{}", blind.output());
    drop(blind);

    // The job was not lost: a runner with Docker does it.
    let runner = RunnerProcess::start(&server.url, &work.path().join("runner"), &RunnerOptions::default());
    let job = finished_job(&server, &ada, &id, Duration::from_secs(300)).await;
    assert_eq!(job["state"], "succeeded", "{job}\n{}", runner.output());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_runner_kept_by_a_server_started_afresh_registers_again() {
    images();
    references(&["experimental/fireflies"]);
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("runner");
    let first = spawn(Db::Sqlite).await;
    let runner = RunnerProcess::start(&first.url, &dir, &RunnerOptions::default());
    runner.wait_for_output(") ready: ", Duration::from_secs(120));
    let kept = runner.id().unwrap();
    drop(runner);
    // The same runner directory beside a server with a new data directory
    // (as when fbksd-data is deleted and fbksd-runner kept): the kept
    // identity is unknown there, so the runner registers again and works.
    let second = spawn(Db::Sqlite).await;
    let runner = RunnerProcess::start(&second.url, &dir, &RunnerOptions::default());
    runner.wait_for_output("registering again", Duration::from_secs(60));
    runner.wait_for_output(") ready: ", Duration::from_secs(120));
    assert!(runner.id().is_some_and(|id| id != kept), "{}", runner.output());
    std::thread::sleep(Duration::from_secs(3)); // a few claims
    assert!(!runner.output().contains("unknown runner token"), "{}", runner.output());
}
