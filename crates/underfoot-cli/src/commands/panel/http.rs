//! The panel's HTTP server: the page, the JSON API, the status WebSocket, and the guard
//! every request passes (host, token, origin; see the [module docs](super)).

use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::body::{Body, Bytes};
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{DefaultBodyLimit, Path, Query, Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{any, get, post};
use futures_util::{SinkExt, StreamExt};
use serde::Deserialize;
use serde_json::json;
use underfoot::live::{Marker, RemoteCommand};
use underfoot::units::Decibels;

use super::fitting::{self, MAX_UPLOAD};
use super::state::{Model, Shared, truncate};

const INDEX: &str = include_str!("assets/index.html");
const SCRIPT: &str = include_str!("assets/panel.js");
const STYLE: &str = include_str!("assets/panel.css");

/// Largest body of a request that is not an upload.
const MAX_BODY: usize = 64 << 10;
/// Largest WebSocket message or frame a client may send (it has nothing to send).
const MAX_WS_MESSAGE: usize = 4 << 10;
/// The trim the page may set, in dB below the configured gain.
const MIN_TRIM_DB: f64 = -120.0;

/// The page's policy: its own files and its own server only.
const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; \
                   connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

/// Serves until [`Shared::shut_down`].
pub fn serve(listener: std::net::TcpListener, shared: &Arc<Shared>) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .enable_time()
        .build()?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::from_std(listener)?;
        accept_loop(listener, router(Arc::clone(shared)), shared.quitting()).await;
        Ok(())
    })
}

/// MiB of upload bodies held in memory at once, over all requests: two recordings at
/// the largest size.
pub const UPLOADS_IN_FLIGHT_MIB: u32 = 128;

/// The longest a client may take to send a request's headers, and to start the next
/// one on a kept-alive connection: a client that holds a connection open without
/// sending (an idle socket, a slowloris) is closed after it.
const HEADER_TIMEOUT: Duration = Duration::from_secs(10);

/// Connections served at once. Beyond it a new connection is closed at once, so that a
/// local process opening hundreds cannot exhaust the panel's file descriptors (256 on
/// some systems) and lock the page out; with [`HEADER_TIMEOUT`] the held ones go soon.
const MAX_CONNECTIONS: usize = 128;

/// Accepts connections until `quit`, each served by hyper with a header-read timeout
/// (WebSocket upgrades included), at most [`MAX_CONNECTIONS`] at once; on `quit`, open
/// connections are asked to close gracefully (a WebSocket ends when the server does).
async fn accept_loop(
    listener: tokio::net::TcpListener,
    app: Router,
    mut quit: tokio::sync::watch::Receiver<bool>,
) {
    use hyper_util::rt::{TokioIo, TokioTimer};
    use hyper_util::service::TowerToHyperService;
    let open = Arc::new(tokio::sync::Semaphore::new(MAX_CONNECTIONS));
    let (closing, _) = tokio::sync::watch::channel(false);
    let mut tasks = tokio::task::JoinSet::new();
    loop {
        let accepted = tokio::select! {
            accepted = listener.accept() => accepted,
            _ = quit.wait_for(|q| *q) => break,
        };
        let Ok((stream, _)) = accepted else {
            // Out of descriptors or a reset before accept: wait a little, go on.
            tokio::time::sleep(Duration::from_millis(50)).await;
            continue;
        };
        let Ok(permit) = Arc::clone(&open).try_acquire_owned() else {
            drop(stream);
            continue;
        };
        let _ = stream.set_nodelay(true);
        let service = TowerToHyperService::new(app.clone());
        let mut closing = closing.subscribe();
        tasks.spawn(async move {
            let connection = hyper::server::conn::http1::Builder::new()
                .timer(TokioTimer::new())
                .header_read_timeout(HEADER_TIMEOUT)
                .serve_connection(TokioIo::new(stream), service)
                .with_upgrades();
            tokio::pin!(connection);
            tokio::select! {
                _ = connection.as_mut() => {}
                _ = closing.changed() => {
                    connection.as_mut().graceful_shutdown();
                    let _ = connection.await;
                }
            }
            drop(permit);
        });
        // Finished connections' tasks are reaped as they end.
        while tasks.try_join_next().is_some() {}
    }
    closing.send_replace(true);
    let _ = tokio::time::timeout(Duration::from_secs(2), async {
        while tasks.join_next().await.is_some() {}
    })
    .await;
}

/// Every route, behind the guard.
pub fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(index))
        .route("/panel.js", get(script))
        .route("/panel.css", get(style))
        .route("/api/status", get(status))
        .route("/api/library", get(library))
        .route("/api/ws", get(websocket))
        .route("/api/v2/channels/{channel}/material", post(set_material))
        .route("/api/v2/channels/{channel}/gain", post(set_gain))
        // Protocol 1 numbered channels from 0: its calls are refused, not obeyed on
        // the neighbouring channel.
        .route("/api/channels/{*rest}", any(protocol_1))
        .route("/api/stop", post(stop))
        .route("/api/markers", post(add_marker))
        .route("/api/session/start", post(start_session))
        .route("/api/session/options", get(session_options))
        .route(
            "/api/uploads",
            post(upload).layer(DefaultBodyLimit::max(MAX_UPLOAD)),
        )
        .route("/api/fit", post(start_fit))
        .route("/api/fit/{id}", get(fit_state))
        .fallback(not_found)
        .layer(DefaultBodyLimit::max(MAX_BODY))
        .layer(middleware::from_fn_with_state(Arc::clone(&shared), guard))
        .with_state(shared)
}

/// What went wrong with a request: its status and a message, sent as
/// `{"error": MESSAGE}`.
struct ApiError {
    status: StatusCode,
    message: String,
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = json!({ "error": self.message }).to_string();
        (
            self.status,
            [(header::CONTENT_TYPE, "application/json")],
            body,
        )
            .into_response()
    }
}

fn error(status: StatusCode, message: impl Into<String>) -> ApiError {
    ApiError {
        status,
        message: message.into(),
    }
}

type ApiResult = Result<Response, ApiError>;

fn json_response(body: String) -> Response {
    (
        [
            (header::CONTENT_TYPE, "application/json"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        body,
    )
        .into_response()
}

/// Whether two tokens are equal, in time that does not depend on where they differ.
fn same_token(given: &[u8], ours: &[u8]) -> bool {
    given.len() == ours.len()
        && given
            .iter()
            .zip(ours)
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0
}

/// The token a request carries: the header, or (for the page and the WebSocket, which
/// cannot set headers on a navigation) the query.
fn token_of<'a>(headers: &'a HeaderMap, query: Option<&'a str>) -> Option<&'a [u8]> {
    if let Some(v) = headers.get("x-underfoot-token") {
        return Some(v.as_bytes());
    }
    query?
        .split('&')
        .find_map(|kv| kv.strip_prefix("token="))
        .map(str::as_bytes)
}

/// Host, origin and token checks, before any handler runs.
async fn guard(State(shared): State<Arc<Shared>>, request: Request, next: Next) -> Response {
    let headers = request.headers();
    // Two Host headers: which one a proxy or the router believed is anyone's guess.
    if headers.get_all(header::HOST).iter().count() > 1 {
        return error(StatusCode::BAD_REQUEST, "more than one Host header").into_response();
    }
    let Some(host) = headers.get(header::HOST).and_then(|h| h.to_str().ok()) else {
        return error(StatusCode::BAD_REQUEST, "no Host header").into_response();
    };
    // A request line in absolute form names its host there too (and HTTP says that one
    // wins): it must be this server as well.
    if let Some(authority) = request.uri().authority()
        && !shared.is_our_host(authority.as_str())
    {
        return error(
            StatusCode::MISDIRECTED_REQUEST,
            format!(
                "this panel serves {}, not {}",
                shared.address(),
                truncate(authority.as_str())
            ),
        )
        .into_response();
    }
    if !shared.is_our_host(host) {
        // A page on another site that resolved its name to this machine (DNS
        // rebinding) names that site here.
        return error(
            StatusCode::MISDIRECTED_REQUEST,
            format!(
                "this panel serves {}, not {}",
                shared.address(),
                truncate(host)
            ),
        )
        .into_response();
    }
    let origin_ok = match headers.get(header::ORIGIN) {
        // Scripts and tools send none; a browser always does on a POST or an upgrade.
        None => true,
        Some(o) => o.to_str().is_ok_and(|o| {
            o.strip_prefix("http://")
                .is_some_and(|h| shared.is_our_host(h))
        }),
    };
    let changes = !matches!(*request.method(), Method::GET | Method::HEAD);
    let upgrade = headers.contains_key(header::UPGRADE);
    if (changes || upgrade) && !origin_ok {
        return error(
            StatusCode::FORBIDDEN,
            "cross-origin request refused: only the panel's own page may steer it",
        )
        .into_response();
    }
    let token = token_of(headers, request.uri().query());
    let token_ok = token.is_some_and(|t| same_token(t, shared.token().as_bytes()));
    if (changes || shared.is_remote()) && !token_ok {
        return error(
            StatusCode::UNAUTHORIZED,
            "missing or wrong token (X-Underfoot-Token: the panel's page carries it; it is \
             printed when the panel starts)",
        )
        .into_response();
    }
    next.run(request).await
}

async fn index(State(shared): State<Arc<Shared>>) -> Response {
    let page = INDEX.replace("{{TOKEN}}", shared.token());
    (
        [
            (
                header::CONTENT_TYPE,
                HeaderValue::from_static("text/html; charset=utf-8"),
            ),
            (
                header::CONTENT_SECURITY_POLICY,
                HeaderValue::from_static(CSP),
            ),
            (header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY")),
            (
                header::REFERRER_POLICY,
                HeaderValue::from_static("no-referrer"),
            ),
            (header::CACHE_CONTROL, HeaderValue::from_static("no-store")),
        ],
        page,
    )
        .into_response()
}

async fn script() -> Response {
    (
        [(header::CONTENT_TYPE, "text/javascript; charset=utf-8")],
        SCRIPT,
    )
        .into_response()
}

async fn style() -> Response {
    ([(header::CONTENT_TYPE, "text/css; charset=utf-8")], STYLE).into_response()
}

async fn not_found() -> ApiError {
    error(StatusCode::NOT_FOUND, "no such page or API")
}

async fn status(State(shared): State<Arc<Shared>>) -> Response {
    json_response(shared.status().to_string())
}

async fn library(State(shared): State<Arc<Shared>>) -> Response {
    let view = shared.session();
    let materials: Vec<_> = view
        .entries
        .iter()
        .map(super::state::Entry::to_json)
        .collect();
    json_response(
        json!({
            "origin": view.origin,
            "saves_to": view.settings.library.as_ref().map(|p| p.display().to_string()),
            "materials": materials,
        })
        .to_string(),
    )
}

/// The status, pushed as it changes (about 50 times a second while the session runs).
async fn websocket(State(shared): State<Arc<Shared>>, upgrade: WebSocketUpgrade) -> Response {
    upgrade
        .max_message_size(MAX_WS_MESSAGE)
        .max_frame_size(MAX_WS_MESSAGE)
        .on_upgrade(move |socket| stream_status(socket, shared))
}

async fn stream_status(socket: WebSocket, shared: Arc<Shared>) {
    use futures_util::future::{Either, select};
    let (mut sink, mut stream) = socket.split();
    // The client has nothing to say: what it sends is read (so that pings are answered
    // and a close is seen) and dropped.
    let mut reader = tokio::spawn(async move {
        while let Some(Ok(message)) = stream.next().await {
            if matches!(message, Message::Close(_)) {
                break;
            }
        }
    });
    let mut status = shared.subscribe();
    let mut quit = shared.quitting();
    loop {
        let text = status.borrow_and_update().to_string();
        if sink.send(Message::Text(text.into())).await.is_err() {
            break;
        }
        let next = std::pin::pin!(status.changed());
        let quitting = std::pin::pin!(quit.wait_for(|q| *q));
        match select(select(next, quitting), &mut reader).await {
            Either::Left((Either::Left((Ok(()), _)), _)) => {}
            _ => break,
        }
    }
    let _ = sink.send(Message::Close(None)).await;
    reader.abort();
}

/// A request's JSON body, or a 400 that says what is wrong with it.
fn parse<T: for<'de> Deserialize<'de>>(body: &Bytes) -> Result<T, ApiError> {
    serde_json::from_slice(body).map_err(|e| {
        error(
            StatusCode::BAD_REQUEST,
            format!("the request's JSON: {}", truncate(&e.to_string())),
        )
    })
}

/// The engine's index of the channel a person calls `text`: channels count from 1.
fn channel_of(text: &str) -> Result<u16, ApiError> {
    match text.parse::<u32>() {
        Ok(n) if n >= 1 && n <= u32::from(u16::MAX) + 1 => Ok((n - 1) as u16),
        _ => Err(error(
            StatusCode::BAD_REQUEST,
            format!(
                "channel {:?}: not a channel number (channels count from 1)",
                truncate(text)
            ),
        )),
    }
}

/// A call of protocol 1 (channels from 0): refused with what to call instead.
async fn protocol_1() -> ApiError {
    error(
        StatusCode::GONE,
        "this is protocol 1's address, whose channels counted from 0; this panel speaks \
         protocol 2: /api/v2/channels/N/material and /api/v2/channels/N/gain, with \
         channels from 1 as the page and the status number them",
    )
}

/// Sends a command to the session from a blocking thread (the session answers within
/// one pass of its loop).
async fn send(shared: &Arc<Shared>, command: RemoteCommand) -> Result<Option<u16>, ApiError> {
    let Some(remote) = shared.session().remote.clone() else {
        return Err(error(StatusCode::CONFLICT, "the session is not running"));
    };
    match tokio::task::spawn_blocking(move || remote.send(command)).await {
        Ok(Ok(slot)) => Ok(slot),
        Ok(Err(e)) => Err(error(StatusCode::CONFLICT, e.to_string())),
        Err(_) => Err(error(
            StatusCode::INTERNAL_SERVER_ERROR,
            "the request failed",
        )),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialRequest {
    material: String,
    #[serde(default)]
    model: Option<Model>,
}

async fn set_material(
    State(shared): State<Arc<Shared>>,
    Path(channel): Path<String>,
    body: Bytes,
) -> ApiResult {
    let channel = channel_of(&channel)?;
    let request: MaterialRequest = parse(&body)?;
    let slot = shared
        .session()
        .slot_of(&request.material, request.model.unwrap_or(Model::Iir))
        .map_err(|e| error(StatusCode::NOT_FOUND, e))?;
    send(&shared, RemoteCommand::Material { channel, slot }).await?;
    Ok(json_response(
        json!({ "channel": channel + 1, "material": request.material, "slot": slot }).to_string(),
    ))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GainRequest {
    trim_db: f64,
}

async fn set_gain(
    State(shared): State<Arc<Shared>>,
    Path(channel): Path<String>,
    body: Bytes,
) -> ApiResult {
    let channel = channel_of(&channel)?;
    let request: GainRequest = parse(&body)?;
    if !(MIN_TRIM_DB..=0.0).contains(&request.trim_db) {
        return Err(error(
            StatusCode::BAD_REQUEST,
            format!(
                "trim_db {}: need {MIN_TRIM_DB} to 0 (the panel can only lower the output \
                 below the configured gain; the limiter's ceiling never moves)",
                request.trim_db
            ),
        ));
    }
    send(
        &shared,
        RemoteCommand::Trim {
            channel,
            gain: Decibels(request.trim_db),
        },
    )
    .await?;
    Ok(json_response(
        json!({ "channel": channel + 1, "trim_db": request.trim_db }).to_string(),
    ))
}

async fn stop(State(shared): State<Arc<Shared>>) -> ApiResult {
    send(&shared, RemoteCommand::Stop).await?;
    Ok(json_response(json!({ "stopping": true }).to_string()))
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct StartRequest {
    input: Option<String>,
    output: Option<String>,
    library: Option<String>,
}

/// A new session, once the last has ended, with the input, output and library the
/// request names (each as its flag takes it; left out: the last session's).
async fn start_session(State(shared): State<Arc<Shared>>, body: Bytes) -> ApiResult {
    let request: StartRequest = if body.iter().all(u8::is_ascii_whitespace) {
        StartRequest::default()
    } else {
        parse(&body)?
    };
    shared
        .request_restart(
            request.input.as_deref(),
            request.output.as_deref(),
            request.library.as_deref(),
        )
        .map_err(|(code, why)| error(code, why))?;
    Ok(json_response(json!({ "starting": true }).to_string()))
}

/// What the page offers to choose from for the next session: the audio devices and
/// serial ports this machine has now, and the current choice. Listing the devices may
/// take a moment (an audio server answering), so it runs off the server's thread.
async fn session_options(State(shared): State<Arc<Shared>>) -> ApiResult {
    let host = shared.audio_host().to_owned();
    let (outputs, ports) = tokio::task::spawn_blocking(move || {
        (
            crate::commands::run::output_offers(&host),
            underfoot::io::serial::list_ports(),
        )
    })
    .await
    .map_err(|_| {
        error(
            StatusCode::INTERNAL_SERVER_ERROR,
            "listing the devices failed",
        )
    })?;
    let mut inputs = vec![
        "gait:steps=4".to_owned(),
        "gait:steps=200".to_owned(),
        "osc:127.0.0.1:9000".to_owned(),
    ];
    inputs.extend(ports.into_iter().map(|p| format!("serial:{p}")));
    Ok(json_response(
        json!({
            "inputs": inputs,
            "outputs": outputs,
            "files_allowed": !shared.is_remote(),
        })
        .to_string(),
    ))
}

/// A marker into the session's record: refused (409, with why) when the session is not
/// recorded or has ended, 400 for a marker the record cannot take.
async fn add_marker(State(shared): State<Arc<Shared>>, body: Bytes) -> ApiResult {
    let marker: Marker = parse(&body)?;
    marker
        .check()
        .map_err(|e| error(StatusCode::BAD_REQUEST, e.to_string()))?;
    send(&shared, RemoteCommand::Marker(marker.clone())).await?;
    let mut view = shared.session();
    let t = view.last.as_ref().map_or(0.0, |s| s.elapsed.as_secs_f64());
    let mut recorded = serde_json::to_value(&marker).unwrap_or_default();
    recorded["elapsed_s"] = json!(t);
    view.markers += 1;
    view.last_marker = Some(recorded.clone());
    Ok(json_response(recorded.to_string()))
}

#[derive(Deserialize)]
struct UploadQuery {
    name: String,
}

async fn upload(
    State(shared): State<Arc<Shared>>,
    query: Result<Query<UploadQuery>, axum::extract::rejection::QueryRejection>,
    headers: HeaderMap,
    body: Body,
) -> ApiResult {
    let Ok(Query(query)) = query else {
        return Err(error(
            StatusCode::BAD_REQUEST,
            "say the recording's file name: /api/uploads?name=FILE.wav",
        ));
    };
    let too_large = || {
        error(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!("a recording of at most {} MiB", MAX_UPLOAD >> 20),
        )
    };
    // A declared size over the cap is refused before a byte is read.
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<usize>().ok());
    if declared.is_some_and(|n| n > MAX_UPLOAD) {
        return Err(too_large());
    }
    // Bodies are held in memory until stored: all uploads in flight share a budget, so
    // that many at once cannot grow the panel without bound (each takes what it declares,
    // or the cap when it declares nothing).
    let mib = declared.unwrap_or(MAX_UPLOAD).div_ceil(1 << 20).max(1) as u32;
    let Ok(_budget) = Arc::clone(&shared.upload_budget).try_acquire_many_owned(mib) else {
        return Err(error(
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "too many uploads at once (at most {} MiB in flight): try again when these \
                 have finished",
                UPLOADS_IN_FLIGHT_MIB
            ),
        ));
    };
    let bytes = axum::body::to_bytes(body, declared.unwrap_or(MAX_UPLOAD).min(MAX_UPLOAD))
        .await
        .map_err(|_| too_large())?;
    let upload = shared
        .uploads
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .add(&query.name, &bytes)
        .map_err(|e| error(StatusCode::BAD_REQUEST, e))?;
    Ok(json_response(
        serde_json::to_string(&upload).unwrap_or_default(),
    ))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FitRequest {
    name: String,
    uploads: Vec<u64>,
}

async fn start_fit(State(shared): State<Arc<Shared>>, body: Bytes) -> ApiResult {
    let request: FitRequest = parse(&body)?;
    let id = fitting::start(&shared, &request.name, &request.uploads)
        .map_err(|e| error(StatusCode::BAD_REQUEST, e))?;
    Ok(json_response(json!({ "id": id }).to_string()))
}

async fn fit_state(State(shared): State<Arc<Shared>>, Path(id): Path<String>) -> ApiResult {
    let state = id
        .parse()
        .ok()
        .and_then(|id| shared.jobs.get(id))
        .ok_or_else(|| error(StatusCode::NOT_FOUND, format!("no fit {:?}", truncate(&id))))?;
    Ok(json_response(
        serde_json::to_string(&state).unwrap_or_default(),
    ))
}
