//! A real browser for the page tests: Debian's Chromium, headless, driven
//! over WebDriver by Debian's `chromedriver` (`deploy/setup.sh` installs
//! both). Tests read what a person sees: screenshots are decoded to
//! pixels, and scripts run in the page only to ask where things are or to
//! wait until the page has drawn.

use fantoccini::{Client, ClientBuilder, Locator};
use std::time::{Duration, Instant};

pub use fantoccini::key::Key;

/// A headless Chromium session (closed, with its driver, on drop).
pub struct Browser {
    client: Client,
    driver: tokio::process::Child,
}

/// The browser's window size in CSS pixels (device pixel ratio 1).
pub const WINDOW: (u32, u32) = (1280, 1600);

impl Browser {
    /// Starts chromedriver on a free port and a headless Chromium on it.
    pub async fn start() -> Browser {
        let port = {
            let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
            listener.local_addr().unwrap().port()
        };
        let driver = tokio::process::Command::new("chromedriver")
            .arg(format!("--port={port}"))
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .kill_on_drop(true)
            .spawn()
            .expect("chromedriver (Debian's chromium-driver; deploy/setup.sh installs it)");
        let capabilities = serde_json::json!({
            "goog:chromeOptions": {
                "binary": "/usr/bin/chromium",
                "args": [
                    "--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                    "--force-device-scale-factor=1", "--force-color-profile=srgb", "--hide-scrollbars",
                    format!("--window-size={},{}", WINDOW.0, WINDOW.1),
                ],
                "prefs": { "download.default_directory": std::env::temp_dir() }
            }
        });
        let serde_json::Value::Object(capabilities) = capabilities else { unreachable!() };
        let deadline = Instant::now() + Duration::from_secs(30);
        let client = loop {
            match ClientBuilder::native()
                .capabilities(capabilities.clone())
                .connect(&format!("http://127.0.0.1:{port}"))
                .await
            {
                Ok(client) => break client,
                Err(e) if Instant::now() < deadline => {
                    let _ = e;
                    tokio::time::sleep(Duration::from_millis(200)).await;
                }
                Err(e) => panic!("no WebDriver session with chromedriver: {e}"),
            }
        };
        Browser { client, driver }
    }

    /// The WebDriver client, for what this helper does not wrap.
    pub fn client(&self) -> &Client {
        &self.client
    }

    /// Opens `url` and waits for the page to load.
    pub async fn goto(&self, url: &str) {
        self.client.goto(url).await.unwrap_or_else(|e| panic!("opening {url}: {e}"));
    }

    /// Logs in to the FBKSD server at `url` with its form, as a person does.
    pub async fn log_in(&self, url: &str, email: &str, password: &str) {
        self.goto(&format!("{url}/login")).await;
        self.fill("input[name=email]", email).await;
        self.fill("input[name=password]", password).await;
        self.click("form button[type=submit]").await;
        self.wait_for(
            "the session",
            &format!("document.body.innerText.includes('Log out {email}')"),
            Duration::from_secs(10),
        )
        .await;
    }

    /// Runs `script` (a function body; `return` gives the value) in the page.
    pub async fn eval(&self, script: &str) -> serde_json::Value {
        self.client.execute(script, Vec::new()).await.unwrap_or_else(|e| panic!("script failed: {e}\n{script}"))
    }

    /// Runs an async function body (`await` allowed) and returns its value.
    pub async fn eval_async(&self, script: &str) -> serde_json::Value {
        let wrapped = format!(
            "const done = arguments[arguments.length - 1]; (async () => {{ {script} }})().then(done, (e) => done({{ error: String(e && e.message || e) }}));"
        );
        self.client.execute_async(&wrapped, Vec::new()).await.unwrap_or_else(|e| panic!("script failed: {e}\n{script}"))
    }

    /// Polls `expression` until it is truthy (returns its value) or panics
    /// with `what` after `within`.
    pub async fn wait_for(&self, what: &str, expression: &str, within: Duration) -> serde_json::Value {
        let deadline = Instant::now() + within;
        loop {
            // Not there yet (an element still missing) counts as false.
            let value = self.eval(&format!("try {{ return ({expression}); }} catch (e) {{ return null; }}")).await;
            let truthy = !matches!(&value, serde_json::Value::Null | serde_json::Value::Bool(false))
                && value != serde_json::json!("")
                && value != serde_json::json!(0);
            if truthy {
                return value;
            }
            if Instant::now() > deadline {
                let text = self.eval("return document.body ? document.body.innerText.slice(0, 4000) : ''").await;
                panic!("waited {within:?} for {what} ({expression}); the page says:\n{}", text.as_str().unwrap_or(""));
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// What is on screen, as pixels (CSS pixel = screenshot pixel).
    pub async fn screenshot(&self) -> image::RgbaImage {
        let png = self.client.screenshot().await.expect("screenshot");
        image::load_from_memory(&png).expect("a PNG screenshot").to_rgba8()
    }

    /// The visible text of the first element matching `css`.
    pub async fn text(&self, css: &str) -> String {
        let element = self.client.find(Locator::Css(css)).await.unwrap_or_else(|e| panic!("no {css}: {e}"));
        element.text().await.unwrap_or_default()
    }

    /// Fills the input named `name` in the first form matching `css`.
    pub async fn fill(&self, css: &str, value: &str) {
        let element = self.client.find(Locator::Css(css)).await.unwrap_or_else(|e| panic!("no {css}: {e}"));
        element.send_keys(value).await.unwrap();
    }

    /// Clicks the first element matching `css`.
    pub async fn click(&self, css: &str) {
        let element = self.client.find(Locator::Css(css)).await.unwrap_or_else(|e| panic!("no {css}: {e}"));
        element.click().await.unwrap_or_else(|e| panic!("clicking {css}: {e}"));
    }

    /// Moves the mouse to a point of the viewport (CSS pixels).
    pub async fn move_mouse(&self, x: f64, y: f64) {
        use fantoccini::actions::{InputSource, MouseActions, PointerAction};
        let actions = MouseActions::new("mouse".into()).then(PointerAction::MoveTo {
            duration: Some(Duration::from_millis(10)),
            x: x.round() as i64,
            y: y.round() as i64,
        });
        self.client.perform_actions(actions).await.expect("moving the mouse");
    }

    /// Drags the mouse with its left button from one viewport point to another.
    pub async fn drag(&self, from: (f64, f64), to: (f64, f64)) {
        use fantoccini::actions::{InputSource, MouseActions, PointerAction, MOUSE_BUTTON_LEFT};
        let point = |(x, y): (f64, f64), ms| PointerAction::MoveTo {
            duration: Some(Duration::from_millis(ms)),
            x: x.round() as i64,
            y: y.round() as i64,
        };
        let actions = MouseActions::new("mouse".into())
            .then(point(from, 10))
            .then(PointerAction::Down { button: MOUSE_BUTTON_LEFT })
            .then(point(((from.0 + to.0) / 2.0, (from.1 + to.1) / 2.0), 50))
            .then(point(to, 50))
            .then(PointerAction::Up { button: MOUSE_BUTTON_LEFT });
        self.client.perform_actions(actions).await.expect("dragging");
    }

    /// Chooses the option of value `value` in the select matching `css`.
    pub async fn select(&self, css: &str, value: &str) {
        let element = self.client.find(Locator::Css(css)).await.unwrap_or_else(|e| panic!("no {css}: {e}"));
        element.select_by_value(value).await.unwrap_or_else(|e| panic!("choosing {value} in {css}: {e}"));
    }

    /// Types `keys` as a user would, into the page's focused element.
    pub async fn press(&self, keys: &str) {
        let body = self.client.find(Locator::Css("body")).await.unwrap();
        body.send_keys(keys).await.unwrap();
    }

    /// Ends the session.
    pub async fn close(mut self) {
        let _ = self.client.clone().close().await;
        let _ = self.driver.kill().await;
    }
}
