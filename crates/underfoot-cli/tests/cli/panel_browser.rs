//! The panel in a real browser: headless Chromium driven through ChromeDriver's WebDriver
//! API (plain HTTP and JSON, through the panel tests' client), against a `panel` on a
//! generated walk with `--output null`. The page must load without console errors, its
//! meters move, its strike markers match the engine's count, a click switches a channel,
//! and an upload of shared recordings becomes a fitted material in the library list. A
//! screenshot is saved in `target/panel-screenshots/` (CI keeps it).
//!
//! Needs `chromium` and `chromedriver` (Debian: chromium, chromium-driver). Without them
//! the test says so and passes, unless `UNDERFOOT_REQUIRE_BROWSER=1` (CI) makes them
//! mandatory.

use std::net::{SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

use super::panel_cmd::{Panel, request};
use crate::common::footsteps_dir;

const CHROMIUM: &str = "/usr/bin/chromium";
const CHROMEDRIVER: &str = "/usr/bin/chromedriver";

/// Whether the browser is here; `None` (with a note) when it is not and not required.
fn browser_present() -> bool {
    // CI's first pass runs while its browser is still being installed: the browser pass
    // comes later, when it is there for sure.
    if std::env::var_os("UNDERFOOT_BROWSER_LATER").is_some() {
        eprintln!("note: skipping: the browser test runs later (UNDERFOOT_BROWSER_LATER)");
        return false;
    }
    if Path::new(CHROMIUM).exists() && Path::new(CHROMEDRIVER).exists() {
        return true;
    }
    assert!(
        std::env::var("UNDERFOOT_REQUIRE_BROWSER")
            .ok()
            .is_none_or(|v| v != "1"),
        "UNDERFOOT_REQUIRE_BROWSER=1 but {CHROMIUM} or {CHROMEDRIVER} is missing \
         (apt-get install chromium chromium-driver)"
    );
    eprintln!(
        "note: skipping: no {CHROMIUM} and {CHROMEDRIVER} (Debian: chromium, chromium-driver)"
    );
    false
}

/// ChromeDriver and one browser session, both ended when dropped.
struct Browser {
    driver: Child,
    addr: SocketAddr,
    session: String,
}

impl Browser {
    fn start() -> Self {
        let port = TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let driver = Command::new(CHROMEDRIVER)
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start chromedriver");
        let addr: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
        let start = Instant::now();
        while std::net::TcpStream::connect(addr).is_err() {
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "chromedriver did not start"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        let mut browser = Self {
            driver,
            addr,
            session: String::new(),
        };
        let profile = tempfile::tempdir().unwrap().keep();
        let created = browser.call(
            "POST",
            "/session",
            &json!({ "capabilities": { "alwaysMatch": {
                "browserName": "chrome",
                "goog:chromeOptions": {
                    "binary": CHROMIUM,
                    // As the machine's notes say: no background networking on a closed
                    // network, a fresh profile, no sandbox as root.
                    "args": [
                        "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                        "--no-first-run", "--disable-background-networking",
                        "--disable-component-update", "--disable-sync",
                        "--window-size=1280,1700",
                        format!("--user-data-dir={}", profile.display()),
                    ],
                },
                "goog:loggingPrefs": { "browser": "ALL" },
            }}}),
        );
        browser.session = created["sessionId"]
            .as_str()
            .unwrap_or_else(|| panic!("no browser session: {created}"))
            .to_owned();
        browser
    }

    /// A WebDriver command; its `value`.
    fn call(&self, method: &str, path: &str, body: &Value) -> Value {
        let body = if method == "GET" {
            String::new()
        } else {
            body.to_string()
        };
        let r = request(
            self.addr,
            method,
            path,
            &[("Content-Type", "application/json")],
            body.as_bytes(),
        );
        let v: Value = serde_json::from_str(&r.body)
            .unwrap_or_else(|e| panic!("{method} {path}: {e}: {}", r.body));
        assert!(r.status == 200, "{method} {path}: {} {v}", r.status);
        v["value"].clone()
    }

    fn session_call(&self, method: &str, path: &str, body: &Value) -> Value {
        self.call(method, &format!("/session/{}{path}", self.session), body)
    }

    fn script(&self, script: &str) -> Value {
        self.session_call(
            "POST",
            "/execute/sync",
            &json!({ "script": script, "args": [] }),
        )
    }

    fn find(&self, css: &str) -> String {
        let e = self.session_call(
            "POST",
            "/element",
            &json!({ "using": "css selector", "value": css }),
        );
        e.as_object()
            .and_then(|o| o.values().next())
            .and_then(Value::as_str)
            .unwrap_or_else(|| panic!("no element {css}: {e}"))
            .to_owned()
    }

    fn click(&self, css: &str) {
        let id = self.find(css);
        self.session_call("POST", &format!("/element/{id}/click"), &json!({}));
    }

    fn type_into(&self, css: &str, text: &str) {
        let id = self.find(css);
        self.session_call(
            "POST",
            &format!("/element/{id}/value"),
            &json!({ "text": text }),
        );
    }

    /// Waits (up to `within`) for `script` to return true.
    fn wait_for(&self, within: Duration, what: &str, script: &str) {
        let start = Instant::now();
        while self.script(script) != Value::Bool(true) {
            assert!(start.elapsed() < within, "{what}: not within {within:?}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    fn screenshot(&self, to: &Path) {
        let b64 = self.session_call("GET", "/screenshot", &Value::Null);
        let png = base64_decode(b64.as_str().unwrap());
        assert!(png.starts_with(b"\x89PNG"), "a PNG");
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::write(to, png).unwrap();
    }

    /// The browser's console messages of level SEVERE.
    fn console_errors(&self) -> Vec<String> {
        let log = self.session_call("POST", "/se/log", &json!({ "type": "browser" }));
        log.as_array()
            .unwrap()
            .iter()
            .filter(|e| e["level"] == "SEVERE")
            .map(|e| e["message"].as_str().unwrap_or_default().to_owned())
            .collect()
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        if !self.session.is_empty() {
            let _ = request(
                self.addr,
                "DELETE",
                &format!("/session/{}", self.session),
                &[],
                b"",
            );
        }
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

fn base64_decode(text: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        _ => 63,
    };
    let bytes: Vec<u8> = text
        .bytes()
        .filter(|c| *c != b'=' && !c.is_ascii_whitespace())
        .collect();
    let mut out = Vec::with_capacity(bytes.len() * 3 / 4);
    for chunk in bytes.chunks(4) {
        let n = chunk.iter().enumerate().fold(0u32, |acc, (i, c)| {
            acc | u32::from(value(*c)) << (18 - 6 * i)
        });
        let take = chunk.len() - 1;
        out.extend_from_slice(&n.to_be_bytes()[1..=take]);
    }
    out
}

/// Where CI keeps the screenshots.
/// A script that returns, for the SVG figure at `selector`, every pair of its texts
/// whose rendered boxes cross by more than a pixel both ways, and every text that runs
/// past the figure; `[]` when there are none. The boxes are the browser's own
/// (`getBoundingClientRect`, after rotation), so this checks what a person sees.
fn text_layout_problems(selector: &str) -> String {
    format!(
        "const svg = document.querySelector('{selector}');
         if (!svg) return ['no figure at {selector}'];
         const frame = svg.getBoundingClientRect();
         const texts = [...svg.querySelectorAll('text')]
           .filter((t) => t.textContent.trim())
           .map((t) => [t.textContent, t.getBoundingClientRect()]);
         const problems = [];
         texts.forEach(([a, r], i) => {{
           if (r.left < frame.left - 1 || r.right > frame.right + 1
               || r.top < frame.top - 1 || r.bottom > frame.bottom + 1) {{
             problems.push(`${{a}} runs past the figure`);
           }}
           for (const [b, q] of texts.slice(i + 1)) {{
             const across = Math.min(r.right, q.right) - Math.max(r.left, q.left);
             const down = Math.min(r.bottom, q.bottom) - Math.max(r.top, q.top);
             if (across > 1 && down > 1) problems.push(`${{a}} overlaps ${{b}}`);
           }}
         }});
         return problems;"
    )
}

fn screenshots() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target"),
        PathBuf::from,
    );
    target.join("panel-screenshots")
}

#[test]
#[ignore = "slow tier: a headless browser on a paced session and a fit (about 40 s)"]
fn the_panel_works_in_a_headless_browser() {
    if !browser_present() {
        return;
    }
    let Some(data) = footsteps_dir() else { return };
    // A --library that does not exist yet: the built-in materials play until the fit
    // from the page creates it.
    let panel = Panel::start(&[
        "--input",
        "gait:steps=120,channels=2",
        "--output",
        "null",
        "--library",
        "lab.json",
        "--record",
        "rec",
    ]);
    assert!(!panel.tmp.path().join("lab.json").exists());
    let browser = Browser::start();
    let url = format!("http://{}/", panel.addr);
    browser.session_call("POST", "/url", &json!({ "url": url }));
    browser.wait_for(
        Duration::from_secs(10),
        "the page hearing the engine",
        "return document.body.dataset.strikes !== undefined && \
         document.querySelectorAll('article.channel').length === 2 && \
         document.querySelectorAll('#library tbody tr').length > 5 && \
         document.querySelector('#link').textContent === 'live' && \
         document.querySelector('#banner').hidden",
    );
    // Every control says what it does: a help line of its own or its label's.
    let silent = browser.script(
        "return [...document.querySelectorAll('input, select, button, textarea, [tabindex]')] \
         .filter(e => !(e.title || (e.closest('label') && e.closest('label').title))) \
         .map(e => e.id || e.className || e.outerHTML.slice(0, 80))",
    );
    assert_eq!(silent, json!([]), "controls without a help line");
    // While the session runs, its input, output and library are shown, not editable.
    let shown = browser.script(
        "return ['#set-input', '#set-output', '#set-library'].map(s => \
         [document.querySelector(s).value, document.querySelector(s).disabled])",
    );
    assert_eq!(
        shown,
        json!([
            ["gait:steps=120,channels=2", true],
            ["null", true],
            ["lab.json", true]
        ])
    );
    // The meters move: the output meter's width and the force values change.
    let sample = "return [...document.querySelectorAll('article.channel')].map(a => \
                  a.querySelector('.out i.peak').style.width + '|' + \
                  a.querySelector('.force .value').textContent).join(';')";
    let first = browser.script(sample);
    let start = Instant::now();
    let mut seen = std::collections::HashSet::new();
    while start.elapsed() < Duration::from_secs(4) {
        seen.insert(browser.script(sample).to_string());
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        seen.len() >= 10,
        "the meters barely moved: {first} then {seen:?}"
    );
    // Strike markers: one per strike the engine counted while the page watched.
    browser.wait_for(
        Duration::from_secs(10),
        "strike markers",
        "return Number(document.body.dataset.markers) >= 4",
    );
    let counts = browser.script(
        "return [Number(document.body.dataset.markers), Number(document.body.dataset.strikes), \
         Number(document.body.dataset.strikesBase)]",
    );
    let [markers, strikes, base] = [0, 1, 2].map(|i| counts[i].as_u64().unwrap());
    assert_eq!(
        markers,
        strikes - base,
        "markers {markers}, strikes {strikes} from {base}"
    );
    let engine = panel.status();
    let engine_strikes = engine["engine"]["strikes"].as_u64().unwrap();
    assert!(
        engine_strikes >= strikes && engine_strikes <= strikes + 2,
        "the page's count {strikes} is the engine's {engine_strikes}"
    );

    // A click switches channel 2 to sand.
    browser.click("article[data-channel='1'] select.material option[value='sand']");
    panel.wait_for(
        Duration::from_secs(5),
        "channel 2 on sand, from the page",
        |s| s["channels"][1]["material"] == "sand",
    );
    browser.wait_for(
        Duration::from_secs(5),
        "the page showing it",
        "return document.querySelector(\"article[data-channel='1'] h3\").textContent.includes('sand')",
    );

    // An upload of shared recordings becomes a fitted material in the library list.
    let files: Vec<String> = (1..=3)
        .map(|n| {
            data.join(format!("gravel/default_gravel_footstep.{n}.ogg"))
                .canonicalize()
                .unwrap()
                .display()
                .to_string()
        })
        .collect();
    browser.type_into("#files", &files.join("\n"));
    browser.wait_for(
        Duration::from_secs(20),
        "three uploads",
        "return document.querySelectorAll('#uploads li').length === 3 && \
         !document.querySelector('#fit-button').disabled",
    );
    browser.type_into("#fit-name", "lab-gravel");
    browser.click("#fit-button");
    browser.wait_for(
        Duration::from_secs(120),
        "the fitted material in the library list",
        "return [...document.querySelectorAll('#library tbody tr')].some(r => r.dataset.material === 'lab-gravel') \
         && document.querySelector('#fit-result').textContent.includes('lab-gravel')",
    );
    let result = browser.script("return document.querySelector('#fit-result').textContent");
    assert!(
        result.as_str().unwrap().contains("lab-gravel: order"),
        "{result}"
    );
    assert!(panel.library_names().iter().any(|n| n == "lab-gravel"));
    let saved = underfoot::material::Library::load(panel.tmp.path().join("lab.json")).unwrap();
    assert_eq!(saved.names(), ["lab-gravel"], "the fit created the library");
    browser.script("window.scrollTo(0, 0)");
    std::thread::sleep(Duration::from_millis(500));
    let shot = screenshots().join("panel.png");
    browser.screenshot(&shot);
    eprintln!("screenshot: {}", shot.display());
    // A library row shows its response and its physical model's parameters.
    browser.click("#library tbody tr[data-material='gravel']");
    browser.wait_for(
        Duration::from_secs(5),
        "gravel's response and parameters",
        "return document.querySelector('#response svg').textContent.includes('gravel: order') && \
         document.querySelector('#response .params').textContent.includes('event-rate scale a') && \
         !document.querySelector('#response .params').textContent.includes('undefined') && \
         / Hz to [0-9.]+ Hz/.test(document.querySelector('#response .params').textContent)",
    );
    // The panel's figures pass the same layout check as the CLI's, measured by the
    // browser itself: no text over another, none past the figure's edge.
    for figure in ["#response svg", "#fit-result svg"] {
        let problems = browser.script(&text_layout_problems(figure));
        assert_eq!(problems, serde_json::json!([]), "{figure}");
    }
    browser.script("document.querySelector('#library-section').scrollIntoView()");
    std::thread::sleep(Duration::from_millis(300));
    browser.screenshot(&screenshots().join("panel-library.png"));
    browser.script("document.querySelector('#fit-section').scrollIntoView()");
    std::thread::sleep(Duration::from_millis(300));
    browser.screenshot(&screenshots().join("panel-fit.png"));

    // The trial bar: a participant, two trials started, a note; each reaches the record.
    browser.script("document.querySelector('#trial-section').scrollIntoView()");
    browser.type_into("#participant", "P07");
    browser.click("#next-trial");
    browser.wait_for(
        Duration::from_secs(5),
        "the first marker listed",
        "return document.querySelectorAll('#markers li').length === 1",
    );
    browser.click("#next-trial");
    browser.wait_for(
        Duration::from_secs(5),
        "the second marker listed",
        "return document.querySelectorAll('#markers li').length === 2",
    );
    browser.type_into("#marker-text", "stepped off the tile");
    browser.click("#mark");
    browser.wait_for(
        Duration::from_secs(5),
        "the note listed",
        "return document.querySelectorAll('#markers li').length === 3",
    );
    panel.wait_for(Duration::from_secs(5), "three markers in the status", |s| {
        s["markers"] == 3
    });

    // The page at a desktop's, a small laptop's and a phone's width.
    for (width, height) in [(1400, 1000), (800, 600), (390, 844)] {
        browser.session_call(
            "POST",
            "/window/rect",
            &json!({ "width": width, "height": height }),
        );
        std::thread::sleep(Duration::from_millis(400));
        browser.script("window.scrollTo(0, 0)");
        let overflow = browser.script(
            "return document.documentElement.scrollWidth - document.documentElement.clientWidth",
        );
        browser.screenshot(&screenshots().join(format!("panel-{width}.png")));
        browser.script("document.querySelector('#channels-section').scrollIntoView()");
        std::thread::sleep(Duration::from_millis(300));
        browser.screenshot(&screenshots().join(format!("panel-{width}-channels.png")));
        browser.script("document.querySelector('#library-section').scrollIntoView()");
        std::thread::sleep(Duration::from_millis(300));
        browser.screenshot(&screenshots().join(format!("panel-{width}-library.png")));
        browser.script("window.scrollTo(0, 0)");
        assert!(
            overflow.as_i64().unwrap() <= 0,
            "at {width} px the page is {overflow} px wider than the window"
        );
    }

    // STOP: the session fades out and ends; no channel says its input is live.
    browser.click("#stop");
    panel.wait_for(Duration::from_secs(10), "the session ended", |s| {
        s["state"] != "running"
    });
    browser.wait_for(
        Duration::from_secs(5),
        "every badge stopped",
        "return [...document.querySelectorAll('.watchdog')].every(b => b.textContent === 'stopped')",
    );
    let live = browser.script("return document.body.textContent.includes('sensor input: live')");
    assert_eq!(live, json!(false));
    // The one reason it ended.
    let banner = browser.script("return document.querySelector('#banner').textContent");
    assert!(
        banner.as_str().unwrap().contains(": STOP was pressed"),
        "{banner}"
    );
    browser.screenshot(&screenshots().join("panel-stopped.png"));
    // The markers from the page are in the record, in order, with the trial bar's fields.
    let record = panel.tmp.path().join("rec");
    let events = crate::common::ended_record_events(&record);
    let markers: Vec<&Value> = events.iter().filter(|e| e["kind"] == "marker").collect();
    assert_eq!(markers.len(), 3, "{events:?}");
    assert_eq!(markers[0]["text"], "trial 1 starts");
    assert_eq!(markers[1]["trial"], 2);
    assert_eq!(markers[2]["text"], "stepped off the tile");
    assert!(markers.iter().all(|m| m["participant"] == "P07"));
    assert!(
        events
            .iter()
            .any(|e| e["kind"] == "material" && e["material"] == "sand")
    );
    assert_eq!(events.last().unwrap()["reason"], "remote_stop");

    // Started again from the page: a new session, the fit still listed (read back from
    // the library it created), recording into rec-2, with the output chosen on the page.
    browser.wait_for(
        Duration::from_secs(5),
        "the session's fields open for the next one",
        "return !document.querySelector('#set-output').disabled && \
         document.querySelector('#set-output').value === 'null' && \
         document.querySelectorAll('#output-offers option').length >= 1",
    );
    browser.script("document.querySelector('#set-output').value = 'wav:chosen.wav'");
    browser.click("#restart");
    let again = panel.wait_for(Duration::from_secs(20), "running again", |s| {
        s["state"] == "running"
    });
    assert_eq!(again["settings"]["output"], "wav:chosen.wav", "{again}");
    assert_eq!(again["settings"]["input"], "gait:steps=120,channels=2");
    browser.wait_for(
        Duration::from_secs(10),
        "the page live again with the fit listed",
        "return document.querySelector('#link').textContent === 'live' && \
         document.querySelector('#restart').hidden && \
         [...document.querySelectorAll('#library tbody tr')].some(r => r.dataset.material === 'lab-gravel') && \
         document.querySelector('#record-where').textContent.includes('rec-2')",
    );

    let errors = browser.console_errors();
    assert!(errors.is_empty(), "console errors: {errors:?}");
}
