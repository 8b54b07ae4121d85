// Live job log: appends server-sent `log` events to the <pre id="log">
// until the `end` event, which carries the job's final state.
(function () {
  const log = document.getElementById("log");
  if (!log || log.dataset.live !== "true") return;
  const state = document.getElementById("job-state");
  // The page already holds the log so far; the stream starts over, so clear it.
  const events = new EventSource("/api/v1/jobs/" + log.dataset.job + "/log/stream");
  let first = true;
  events.addEventListener("log", (event) => {
    if (first) { log.textContent = ""; first = false; }
    log.textContent += event.data.endsWith("\n") ? event.data : event.data + "\n";
    log.scrollTop = log.scrollHeight;
  });
  events.addEventListener("end", (event) => {
    events.close();
    if (state) { state.textContent = event.data; state.className = "state-" + event.data; }
  });
})();
