//! `underfoot panel`: `run`'s session, watched and steered from a web page served by the
//! same process.
//!
//! The session is `run`'s (every option of `run`, the same engine, inputs, outputs,
//! safety stages and compensation); this command adds an HTTP server beside it
//! (`--listen`, loopback by default) with
//!
//! - `/`: the page (embedded in the binary with its script and style sheet; no CDN, no
//!   build step), which shows each channel's levels live and steers the session;
//! - `/api/ws`: a WebSocket of the session's status, one JSON text per pass of the
//!   session's loop (about 50 a second);
//! - `GET /api/status`: the latest status; `GET /api/library`: the materials, their
//!   fit figures and responses; `POST /api/channels/N/material` (`{"material": NAME,
//!   "model": "iir"|"physical"}`), `POST /api/channels/N/gain` (`{"trim_db": DB}`, -40
//!   to 0), `POST /api/stop`; `POST /api/uploads?name=FILE` (a recording's bytes),
//!   `POST /api/fit` (`{"name": NAME, "uploads": [ID...]}`), `GET /api/fit/ID`;
//!   `POST /api/markers` (`{"text": TEXT, "trial": N, "participant": P, "condition": C}`,
//!   all but the text optional), a marker into the session's record (`--record DIR`);
//!   `POST /api/session/start` (`{"input": SOURCE, "output": SINK, "library": FILE}`,
//!   each optional, each as its flag takes it; an empty library is the built-in one): a
//!   new session once the last has ended, with the page's choice in place of the last
//!   session's (the rest of the command line kept; the library reloaded; a record into
//!   `DIR-2`, `DIR-3`...); `GET /api/session/options`: what the page offers to choose
//!   from (generated walks, an OSC port, this machine's serial ports and audio outputs).
//!   A panel that serves other machines takes no file from the page (a replay, a WAV
//!   output, a library): a token-holder elsewhere could otherwise name any file this
//!   user may write.
//!
//! A `--library` that does not exist yet plays the built-in materials, and the first fit
//! from the page creates it. A session that fails to start (a broken library, a device
//! that does not open) is shown on the page with its error, and can be started again.
//!
//! # Why axum
//! axum on tokio and hyper: hyper is the most used HTTP implementation in Rust, fuzzed
//! upstream, so the panel parses no HTTP itself; axum adds the routing, JSON and
//! WebSocket (tungstenite) on top with typed extractors whose rejections are 4xx
//! responses, never panics. It is behind the `panel` feature, like audio, so the default
//! build (and the quick start) does not compile it. The runtime is a single-threaded
//! tokio on a thread of its own: a handful of local clients need no more.
//!
//! # The audio thread never waits for the page
//! Levels and counters come from the session's status, which the session's own thread
//! reads from the engine's atomics; steering goes through [`underfoot::live::Remote`]
//! to the session's thread and from there through the engine's lock-free command queue;
//! a material fitted from the page is prepared on the fitting thread and reaches the
//! engine as a pointer into a spare slot of its bank (32 are reserved).
//!
//! # Security
//! - Loopback only unless `--allow-remote` is given with a non-loopback `--listen`.
//! - A random token (128 bits) is made at start. Every state-changing request needs it
//!   (`X-Underfoot-Token`), and, when it has an `Origin`, one naming this server; the
//!   WebSocket upgrade checks the `Origin` too. On loopback the page carries the token;
//!   with `--allow-remote`, every request needs it (the printed address carries it as
//!   `?token=`). The `Host` header must name this server (against DNS rebinding).
//! - Uploads go into a temporary folder the panel makes and removes
//!   (`underfoot-panel-PID-...`; a killed panel's is removed by the next one to start),
//!   under names it chooses (`upload-N.EXT`); a request's file name is only a label, and no path in any
//!   request reaches the file system. Uploads are capped (64 MiB each, 64 files, 512 MiB
//!   in all), request bodies elsewhere at 64 KiB, WebSocket messages at 4 KiB.
//! - A fitted material is added to `--library` (when given) with `fit`'s atomic, locked
//!   write; without it, it lives in this session only.

#[cfg(feature = "panel")]
mod fitting;
#[cfg(feature = "panel")]
mod http;
#[cfg(feature = "panel")]
mod state;

use std::net::SocketAddr;

use clap::Args;

use crate::commands::run::RunArgs;

/// Arguments of `underfoot panel`.
#[derive(Debug, Args)]
pub struct PanelArgs {
    /// Where the page is served: ADDR:PORT (port 0: any free port, printed).
    #[arg(long, default_value = "127.0.0.1:8080", value_name = "ADDR:PORT")]
    listen: SocketAddr,
    /// Allow a --listen address that is not loopback: other machines can then reach
    /// the panel, and every request needs the token printed at start.
    #[arg(long = "allow-remote")]
    allow_remote: bool,
    #[command(flatten)]
    run: RunArgs,
}

/// Runs `underfoot panel` (this build has no panel).
#[cfg(not(feature = "panel"))]
pub fn run(_args: &PanelArgs) -> anyhow::Result<()> {
    anyhow::bail!(
        "this build has no panel: rebuild with `--features panel` (cargo install --path \
         crates/underfoot-cli --features panel)"
    )
}

/// Runs `underfoot panel`.
#[cfg(feature = "panel")]
pub fn run(args: &PanelArgs) -> anyhow::Result<()> {
    use std::net::TcpListener;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::thread;

    use anyhow::Context;

    use crate::commands::run::run_session;
    use state::Shared;

    if crate::commands::run::precheck(&args.run)?.is_some() {
        return Ok(());
    }
    let remote = !args.listen.ip().is_loopback();
    anyhow::ensure!(
        !remote || args.allow_remote,
        "--listen {}: not a loopback address; add --allow-remote to serve other machines \
         (every request then needs the token printed at start)",
        args.listen
    );
    // Bound before the session starts: a port in use is said before anything plays.
    let listener = TcpListener::bind(args.listen)
        .with_context(|| format!("--listen {}: cannot listen there", args.listen))?;
    listener
        .set_nonblocking(true)
        .context("setting up the listening socket")?;
    let address = listener
        .local_addr()
        .context("reading the listening address")?;
    let shared = Arc::new(Shared::new(
        address,
        remote,
        args.run.settings(),
        args.run.record_path(),
        args.run.audio_host().to_owned(),
    )?);
    let url = if remote {
        format!("http://{address}/?token={}", shared.token())
    } else {
        format!("http://{address}/")
    };
    eprintln!("underfoot: panel on {url}  (open it in a browser)");
    if remote {
        eprintln!(
            "underfoot: serving other machines: every request needs the token {}",
            shared.token()
        );
    }

    let quit = Arc::new(AtomicBool::new(false));
    let stop = Arc::new(AtomicBool::new(false));
    {
        let (quit, stop) = (Arc::clone(&quit), Arc::clone(&stop));
        ctrlc::set_handler(move || {
            stop.store(true, Ordering::SeqCst);
            quit.store(true, Ordering::SeqCst);
        })
        .context("installing the Ctrl-C handler")?;
    }
    let server = {
        let shared = Arc::clone(&shared);
        thread::Builder::new()
            .name("panel-http".into())
            .spawn(move || http::serve(listener, &shared))
            .context("starting the panel's server thread")?
    };
    let mut observer = state::PanelObserver::new(Arc::clone(&shared));
    // One session after another: the page starts the next when one has ended, with the
    // same arguments (the library reloaded, so that fits saved into it play).
    let mut outcome;
    let mut n = 1;
    // The command line's arguments, with each choice the page made since.
    let mut chosen = args.run.clone();
    loop {
        let run = chosen.for_panel_session(n);
        shared.set_session(run.settings(), run.record_path());
        stop.store(false, Ordering::SeqCst);
        outcome = run_session(&run, &stop, Some(&mut observer));
        if let Err(e) = &outcome {
            // The page says why; so does the terminal, now rather than after Ctrl-C.
            eprintln!(
                "underfoot: the session ended on an error: {}",
                crate::message::chain(e)
            );
        }
        if quit.load(Ordering::SeqCst) {
            break;
        }
        eprintln!(
            "underfoot: the session has ended; the panel stays up on {url} (start again from \
             the page; Ctrl-C to quit)"
        );
        let choice = loop {
            if quit.load(Ordering::SeqCst) || server.is_finished() {
                break None;
            }
            if let Some(choice) = shared.take_restart() {
                break Some(choice);
            }
            thread::sleep(std::time::Duration::from_millis(50));
        };
        let Some(choice) = choice else { break };
        chosen.choose(&choice);
        n += 1;
        eprintln!("underfoot: starting session {n}, asked from the page");
    }
    shared.shut_down();
    match server.join() {
        Ok(result) => result.context("the panel's server")?,
        Err(_) => anyhow::bail!("the panel's server thread panicked"),
    }
    outcome
}
