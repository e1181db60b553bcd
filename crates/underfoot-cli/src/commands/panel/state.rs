//! What the panel's server and the session share: the latest status (as JSON, for the
//! WebSocket and `/api/status`), the catalog of playable materials and their bank
//! slots, the handle that steers the session, uploads and fit jobs.
//!
//! The session's thread writes the status through [`PanelObserver`]; the server's thread
//! reads it. Locks here are only ever taken by those two threads and the fitting
//! threads, never by the audio thread.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard};

use axum::http::StatusCode;
use serde::Serialize;
use serde_json::json;
use tokio::sync::watch;
use underfoot::engine::{ChannelLevels, MaterialBank};
use underfoot::live::EndReason;
use underfoot::live::{Remote, RunningSession, Status, Summary};
use underfoot::material::MaterialModel;
use underfoot::synthesis::{PreparedMaterial, SynthModel, VoiceConfig};
use underfoot::units::{Newtons, SampleRate};

use super::fitting::{Jobs, Uploads};
use crate::commands::run::{Observer, SessionChoice, SessionSettings};
use crate::commands::synth::Setup;
use crate::report::{FitReportEntry, LeaveOneOutReport};

/// Bank slots reserved for materials fitted from the page (two per fit: its filter and
/// its physical model).
pub const SPARE_SLOTS: usize = 32;

/// Which of a material's models a slot plays.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Model {
    Iir,
    Physical,
}

/// The slots a material plays from.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Slots {
    pub iir: u16,
    pub physical: Option<u16>,
}

/// A material the page can choose.
pub struct Entry {
    pub model: MaterialModel,
    pub slots: Slots,
    /// Fitted from the page in this session.
    pub added: bool,
    /// The leave-one-out check, for materials fitted from the page (a library does not
    /// keep it).
    pub leave_one_out: Option<LeaveOneOutReport>,
}

impl Entry {
    /// The library's view of the material: the `fit --report` entry, its response on the
    /// fit's grid in dB, and its slots.
    pub fn to_json(&self) -> serde_json::Value {
        let fit = &self.model.fit;
        let mut report = FitReportEntry::of(&self.model);
        report.leave_one_out.clone_from(&self.leave_one_out);
        let to_db = |v: &[f64]| -> Vec<Option<f64>> {
            v.iter()
                .map(|m| (*m > 0.0).then(|| 20.0 * m.log10()))
                .collect()
        };
        json!({
            "name": self.model.name,
            "order": self.model.order,
            "nrmse": fit.nrmse,
            "lsd_db": fit.lsd_db,
            "strikes": fit.strikes,
            "poor_fit": fit.poor_fit,
            "fit_seconds": fit.fit_seconds,
            "physical": report.physical,
            "physical_model": self.model.physical,
            "leave_one_out": report.leave_one_out,
            "sources": report.sources,
            "grid_hz": fit.grid_hz,
            "measured_db": to_db(&fit.measured),
            "model_db": to_db(&fit.model),
            "slots": self.slots,
            "added": self.added,
        })
    }
}

/// How the session's materials were prepared, so that a fitted one is prepared alike.
#[derive(Clone)]
pub struct Preparation {
    pub rate: SampleRate,
    pub voice: VoiceConfig,
    pub nominal_step: Vec<f64>,
    pub weight: Newtons,
}

impl Preparation {
    /// The material's filter, and its physical model if it has one, ready for the engine.
    pub fn prepare(
        &self,
        model: &MaterialModel,
    ) -> anyhow::Result<(PreparedMaterial, Option<PreparedMaterial>)> {
        let one = |kind| -> anyhow::Result<PreparedMaterial> {
            let voice = VoiceConfig {
                model: kind,
                ..self.voice.clone()
            };
            let mut p = PreparedMaterial::prepare(model, self.rate, &voice)?;
            p.normalise_drives(&self.nominal_step, self.weight);
            Ok(p)
        };
        let physical = match model.physical {
            Some(_) => Some(one(SynthModel::Physical)?),
            None => None,
        };
        Ok((one(SynthModel::Iir)?, physical))
    }
}

/// Where the session is.
#[derive(Debug, Clone, PartialEq)]
pub enum Phase {
    Starting,
    Running,
    Ended(String),
    Failed(String),
}

/// The session as the panel sees it.
pub struct SessionView {
    pub remote: Option<Remote>,
    pub entries: Vec<Entry>,
    /// Each bank slot's entry and model.
    pub slots: Vec<(usize, Model)>,
    /// Bumped whenever `entries` changes: the page reloads the library.
    pub version: u64,
    pub origin: String,
    pub preparation: Option<Preparation>,
    pub describe: String,
    pub ceiling_db: f64,
    pub weight: Newtons,
    pub phase: Phase,
    /// The last status, to report again when the session has ended.
    pub last: Option<Status>,
    /// The session's record folder (`--record`), if it is recorded.
    pub record: Option<String>,
    /// The input, output and library the session plays with.
    pub settings: SessionSettings,
    /// Markers taken into the record, and the last one.
    pub markers: u64,
    pub last_marker: Option<serde_json::Value>,
}

impl SessionView {
    /// Records a material and its slots; one of the same name is replaced in the list
    /// (its old slots stay in the bank, unused).
    pub fn add(&mut self, entry: Entry) {
        let index = match self
            .entries
            .iter()
            .position(|e| e.model.name == entry.model.name)
        {
            Some(i) => {
                self.entries[i] = entry;
                i
            }
            None => {
                self.entries.push(entry);
                self.entries.len() - 1
            }
        };
        let slots = self.entries[index].slots;
        for (slot, model) in [
            (Some(slots.iir), Model::Iir),
            (slots.physical, Model::Physical),
        ] {
            if let Some(slot) = slot {
                let slot = usize::from(slot);
                if self.slots.len() <= slot {
                    self.slots.resize(slot + 1, (index, model));
                }
                self.slots[slot] = (index, model);
            }
        }
        self.version += 1;
    }

    /// The slot that plays `name` with `model`.
    pub fn slot_of(&self, name: &str, model: Model) -> Result<u16, String> {
        let entry = self
            .entries
            .iter()
            .find(|e| e.model.name == name)
            .ok_or_else(|| {
                format!(
                    "no material {:?} (there are: {})",
                    truncate(name),
                    self.entries
                        .iter()
                        .map(|e| e.model.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })?;
        match model {
            Model::Iir => Ok(entry.slots.iir),
            Model::Physical => entry
                .slots
                .physical
                .ok_or_else(|| format!("{name} has no physical model")),
        }
    }

    /// The status as the page and the API read it.
    pub fn status_json(&self) -> String {
        let (state, reason) = match &self.phase {
            Phase::Starting => ("starting", String::new()),
            Phase::Running => ("running", String::new()),
            Phase::Ended(r) => ("ended", r.clone()),
            Phase::Failed(r) => ("failed", r.clone()),
        };
        let default = Status::default();
        let s = self.last.as_ref().unwrap_or(&default);
        let t = &s.telemetry;
        // Silence is null, by the library's one rule for it.
        let dbfs = underfoot::safety::level_dbfs;
        let channels: Vec<_> = s
            .channels
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let (material, model) = c
                    .slot
                    .and_then(|slot| self.slots.get(usize::from(slot)))
                    .map_or((None, None), |(e, m)| {
                        (Some(self.entries[*e].model.name.as_str()), Some(*m))
                    });
                json!({
                    "channel": i + 1,
                    "force_n": c.force,
                    "sensors": &c.sensors[..usize::from(c.sensor_count)],
                    "weight_n": self.weight.0,
                    "strikes": c.strikes,
                    "peak_dbfs": dbfs(c.peak),
                    "rms_dbfs": dbfs(c.rms),
                    "drive": c.drive,
                    // `+ 0.0` turns no reduction's -0.0 into 0.0.
                    "gain_reduction_db": (-20.0 * f64::from(c.limiter_gain.max(1e-6)).log10()).max(0.0) + 0.0,
                    "limited": c.limited,
                    "live": c.live,
                    "slot": c.slot,
                    "material": material,
                    "model": model,
                    "trim_db": (20.0 * f64::from(c.trim.max(1e-6)).log10()).max(-120.0),
                })
            })
            .collect();
        let link = if s.input.disconnects > s.input.reconnects {
            "lost"
        } else {
            "open"
        };
        json!({
            "state": state,
            "reason": reason,
            "session": self.describe,
            "elapsed_s": s.elapsed.as_secs_f64(),
            "ceiling_db": self.ceiling_db,
            "latency_ms": s.output_latency.map(|l| l.0 * 1e3),
            "catalog_version": self.version,
            "record": self.record,
            "settings": {
                "input": self.settings.input,
                "output": self.settings.output,
                "library": self.settings.library.as_ref().map(|p| p.display().to_string()),
                "interface": self.settings.interface.as_ref().map(|p| p.display().to_string()),
            },
            "markers": self.markers,
            "last_marker": self.last_marker,
            "input": {
                "events": s.input.events,
                "rejected": s.input.rejected,
                "lost": s.queue_full + t.dropped,
                "disconnects": s.input.disconnects,
                "link": link,
                "rejected_by_reason": s.rejections.iter().map(|(why, n)| (why.to_string(), json!(n))).collect::<serde_json::Map<_, _>>(),
                "last_reject": s.last_reject,
            },
            "engine": {
                "frames": t.frames,
                "strikes": t.strikes,
                "late_buffers": s.late_buffers,
                "late_readings": t.late,
                "non_finite": t.non_finite,
                "watchdog_trips": t.watchdog_trips,
                "limited": t.limited,
            },
            "channels": channels,
        })
        .to_string()
    }
}

/// Everything the server and the session share.
pub struct Shared {
    token: String,
    address: SocketAddr,
    remote: bool,
    /// `Host` headers that name this server.
    hosts: Vec<String>,
    status: watch::Sender<Arc<str>>,
    quit: watch::Sender<bool>,
    session: Mutex<SessionView>,
    pub uploads: Mutex<Uploads>,
    pub jobs: Jobs,
    /// Set by the page's "start" once the session has ended, with what it chose.
    restart: Mutex<Option<SessionChoice>>,
    /// `--host`: where the page's list of audio outputs comes from.
    audio_host: String,
    /// MiB of upload bodies that may be in memory at once, over all requests.
    pub upload_budget: Arc<tokio::sync::Semaphore>,
}

impl Shared {
    /// The panel's state for a server on `address`.
    pub fn new(
        address: SocketAddr,
        remote: bool,
        settings: SessionSettings,
        record: Option<PathBuf>,
        audio_host: String,
    ) -> anyhow::Result<Self> {
        let port = address.port();
        let mut hosts = vec![
            address.to_string(),
            format!("localhost:{port}"),
            format!("127.0.0.1:{port}"),
            format!("[::1]:{port}"),
        ];
        if port == 80 {
            hosts.extend([
                "localhost".into(),
                "127.0.0.1".into(),
                address.ip().to_string(),
            ]);
        }
        let view = SessionView {
            remote: None,
            entries: Vec::new(),
            slots: Vec::new(),
            version: 0,
            origin: String::new(),
            preparation: None,
            describe: "starting".into(),
            ceiling_db: 0.0,
            weight: Newtons::weight_of(70.0),
            phase: Phase::Starting,
            last: None,
            record: record.map(|p| p.display().to_string()),
            settings,
            markers: 0,
            last_marker: None,
        };
        let first: Arc<str> = view.status_json().into();
        Ok(Self {
            token: token(),
            address,
            remote,
            hosts,
            status: watch::Sender::new(first),
            quit: watch::Sender::new(false),
            session: Mutex::new(view),
            uploads: Mutex::new(Uploads::new()?),
            jobs: Jobs::default(),
            restart: Mutex::new(None),
            audio_host,
            upload_budget: Arc::new(tokio::sync::Semaphore::new(
                super::http::UPLOADS_IN_FLIGHT_MIB as usize,
            )),
        })
    }

    /// Asks for a new session, when the last one has ended, with `choice` of input,
    /// output and library (texts as the flags take them; `None` keeps the last one).
    ///
    /// # Errors
    /// Why not, and the HTTP status that says it: the session is running or starting
    /// (409), or the choice is not one the panel takes (400).
    pub fn request_restart(
        &self,
        input: Option<&str>,
        output: Option<&str>,
        library: Option<&str>,
    ) -> Result<(), (StatusCode, String)> {
        let mut view = self.session();
        match view.phase {
            Phase::Ended(_) | Phase::Failed(_) => {
                let choice =
                    SessionChoice::parse(input, output, library, &view.settings, !self.remote)
                        .map_err(|why| (StatusCode::BAD_REQUEST, why))?;
                *self
                    .restart
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(choice);
                view.phase = Phase::Starting;
                view.remote = None;
                self.publish(&view);
                Ok(())
            }
            Phase::Starting => Err((StatusCode::CONFLICT, "the session is starting".into())),
            Phase::Running => Err((
                StatusCode::CONFLICT,
                "the session is running: STOP it first".into(),
            )),
        }
    }

    /// Takes a restart request, if the page made one: what it chose.
    pub fn take_restart(&self) -> Option<SessionChoice> {
        self.restart
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take()
    }

    /// What the next session plays with and where it records, as the page shows it.
    pub fn set_session(&self, settings: SessionSettings, record: Option<PathBuf>) {
        let mut view = self.session();
        view.settings = settings;
        view.record = record.map(|p| p.display().to_string());
        view.markers = 0;
        view.last_marker = None;
        self.publish(&view);
    }

    /// Where fitted materials are saved (the session's library), if anywhere.
    pub fn library(&self) -> Option<PathBuf> {
        self.session().settings.library.clone()
    }

    /// The audio host (`--host`) whose devices the page offers.
    pub fn audio_host(&self) -> &str {
        &self.audio_host
    }

    /// The token state-changing requests carry.
    pub fn token(&self) -> &str {
        &self.token
    }

    /// Whether other machines may connect (every request then needs the token).
    pub fn is_remote(&self) -> bool {
        self.remote
    }

    /// The address served.
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Whether `host` (a `Host` header) names this server. With `--allow-remote` the
    /// machine may be reached under any name, and the token guards every request.
    pub fn is_our_host(&self, host: &str) -> bool {
        self.remote || self.hosts.iter().any(|h| h.eq_ignore_ascii_case(host))
    }

    /// The session's view (locks: never held across an await or a wait).
    pub fn session(&self) -> MutexGuard<'_, SessionView> {
        // A panic while holding it would be a bug elsewhere; the view itself is still
        // consistent enough to show.
        self.session
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The latest status, and a way to wait for the next.
    pub fn subscribe(&self) -> watch::Receiver<Arc<str>> {
        self.status.subscribe()
    }

    /// The latest status.
    pub fn status(&self) -> Arc<str> {
        self.status.borrow().clone()
    }

    fn publish(&self, view: &SessionView) {
        self.status.send_replace(view.status_json().into());
    }

    /// Tells the server to finish: open WebSockets close, then it stops listening.
    pub fn shut_down(&self) {
        self.quit.send_replace(true);
    }

    /// Resolves when [`shut_down`](Self::shut_down) has been called.
    pub fn quitting(&self) -> watch::Receiver<bool> {
        self.quit.subscribe()
    }
}

/// A random token of 128 bits, from the standard library's OS-seeded hasher keys (no
/// extra dependency; each `RandomState` draws fresh keys).
fn token() -> String {
    use std::hash::{BuildHasher, Hasher};
    let mut out = String::new();
    for i in 0..2u8 {
        let mut h = std::collections::hash_map::RandomState::new().build_hasher();
        h.write_u8(i);
        h.write_u128(
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos()),
        );
        out.push_str(&format!("{:016x}", h.finish()));
    }
    out
}

/// Something a request gave, for a message: a long word cut to its ends.
pub fn truncate(s: &str) -> String {
    crate::message::shorten(s).into_owned()
}

/// The session's side of the panel: what it plays, its status, its end.
pub struct PanelObserver {
    shared: Arc<Shared>,
    /// The output gain and the limiter's ceiling, in dB, for the limiter's warning.
    limits: Option<(f64, f64)>,
}

impl PanelObserver {
    pub fn new(shared: Arc<Shared>) -> Self {
        Self {
            shared,
            limits: None,
        }
    }
}

impl Observer for PanelObserver {
    fn prepare(
        &mut self,
        setup: &mut Setup,
        names: &[String],
        channels: usize,
    ) -> anyhow::Result<Option<Vec<u16>>> {
        let preparation = Preparation {
            rate: setup.config.rate,
            voice: setup.voice.clone(),
            nominal_step: setup.nominal_step.clone(),
            weight: setup.config.nominal_weight,
        };
        // Every material's filter first, in library order (so that names find their
        // filter, as OSC material messages expect), then the physical models.
        // A session started again from the page: the materials fitted in an earlier one
        // and kept for the panel only (no --library) play again, after the library's.
        let kept: Vec<MaterialModel> = {
            let view = self.shared.session();
            view.entries
                .iter()
                .filter(|e| e.added && setup.library.get(&e.model.name).is_err())
                .map(|e| e.model.clone())
                .collect()
        };
        let materials: Vec<MaterialModel> = setup
            .library
            .materials
            .iter()
            .cloned()
            .chain(kept)
            .collect();
        let mut filters = Vec::new();
        let mut physicals = Vec::new();
        for m in &materials {
            let (iir, physical) = preparation.prepare(m)?;
            filters.push(iir);
            physicals.push(physical);
        }
        let mut view = self.shared.session();
        view.entries.clear();
        view.slots.clear();
        let library_count = setup.library.materials.len();
        let mut bank = filters;
        for (i, (m, physical)) in materials.iter().zip(physicals).enumerate() {
            let physical_slot = physical.map(|p| {
                bank.push(p);
                (bank.len() - 1) as u16
            });
            // The same bookkeeping as a material fitted from the page.
            view.add(Entry {
                model: m.clone(),
                slots: Slots {
                    iir: i as u16,
                    physical: physical_slot,
                },
                added: i >= library_count,
                leave_one_out: None,
            });
        }
        let wanted = if setup.voice.model == SynthModel::Physical {
            Model::Physical
        } else {
            Model::Iir
        };
        let first = names
            .iter()
            .map(|name| {
                view.slot_of(name, wanted)
                    .or_else(|_| view.slot_of(name, Model::Iir))
                    .map_err(|e| anyhow::anyhow!("--material: {e} (in {})", setup.origin))
            })
            .collect::<anyhow::Result<Vec<u16>>>()?;
        let last = *first
            .last()
            .ok_or_else(|| anyhow::anyhow!("no material given"))?;
        let slots: Vec<u16> = (0..channels)
            .map(|c| first.get(c).copied().unwrap_or(last))
            .collect();
        // Until the session's first status, each channel shows as silent, on the material
        // it starts with (not as none: a client that reads the status as soon as the
        // session runs sees what is playing).
        view.last = Some(Status {
            channels: slots
                .iter()
                .map(|&slot| ChannelLevels {
                    slot: Some(slot),
                    ..ChannelLevels::default()
                })
                .collect(),
            ..Status::default()
        });
        view.origin = setup.origin.clone();
        view.preparation = Some(preparation);
        view.weight = setup.config.nominal_weight;
        view.ceiling_db = setup.config.ceiling.0;
        setup.bank = MaterialBank::from_prepared(bank);
        setup.config.spare_slots = SPARE_SLOTS;
        Ok(Some(slots))
    }

    fn started(&mut self, session: &RunningSession, setup: &Setup) {
        self.limits = Some((setup.config.gain.0, setup.config.ceiling.0));
        let mut view = self.shared.session();
        view.remote = Some(session.remote());
        view.describe = crate::commands::run::describe(session.output());
        view.phase = Phase::Running;
        view.version += 1;
        self.shared.publish(&view);
    }

    fn status(&mut self, status: &Status) {
        let mut view = self.shared.session();
        match &mut view.last {
            Some(last) => last.clone_from(status),
            None => view.last = Some(status.clone()),
        }
        self.shared.publish(&view);
    }

    fn ended(&mut self, outcome: Result<&Summary, &anyhow::Error>) {
        let mut view = self.shared.session();
        view.remote = None;
        view.phase = match outcome {
            Ok(summary) => Phase::Ended(match &summary.lost {
                Some(event) => {
                    format!("the input was lost ({event}) and --exit-on-disconnect is set")
                }
                None => {
                    format!(
                        "the session ended after {:.1} s: {}",
                        summary.elapsed.as_secs_f64(),
                        match summary.ended {
                            EndReason::RemoteStop => "STOP was pressed".to_owned(),
                            EndReason::Stopped => "the panel was asked to quit (Ctrl-C)".to_owned(),
                            EndReason::Duration => "--duration was over".to_owned(),
                            other => other.to_string(),
                        }
                    ) + &self
                        .limits
                        .and_then(|(gain, ceiling)| {
                            crate::commands::run::status::limiter_warning(
                                &summary.telemetry,
                                gain,
                                ceiling,
                            )
                        })
                        .map_or_else(String::new, |w| format!(". Warning: {w}"))
                }
            }),
            Err(e) => Phase::Failed(crate::message::chain(e)),
        };
        if let (Some(last), Ok(summary)) = (&mut view.last, outcome) {
            last.telemetry = summary.telemetry;
            last.input = summary.input;
        }
        self.shared.publish(&view);
    }
}
