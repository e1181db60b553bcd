//! Recordings uploaded from the page, and the fits made from them.
//!
//! An upload is stored in the panel's temporary folder under a name the panel chooses
//! (`upload-N.EXT`, the extension one of the recording formats, from the name the
//! browser gave, which is otherwise only a label): nothing a request says becomes a
//! path. A fit runs on a thread of its own, as `fit` does (`build_material`, then the
//! leave-one-out check), saves into `--library` with `fit`'s atomic, locked edit, and
//! hands the prepared material to the session as a new bank slot.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use serde::Serialize;
use underfoot::atomic_file::OutputFile;
use underfoot::live::RemoteCommand;
use underfoot::material::Library;
use underfoot::material::build::{BuildConfig, Progress, build_material};
use underfoot::material::library::validate_name;
use underfoot::material::quality::leave_one_out;
use underfoot::recording;

use super::state::{Entry, Shared, Slots, truncate};
use crate::report::LeaveOneOutReport;

/// Largest recording accepted.
pub const MAX_UPLOAD: usize = 64 << 20;
/// Most recordings held at once.
pub const MAX_FILES: usize = 64;
/// Most bytes held at once.
pub const MAX_TOTAL: usize = 512 << 20;
/// Most fits kept (their state, for the page to read).
const MAX_JOBS: usize = 64;

/// One uploaded recording.
#[derive(Debug, Clone, Serialize)]
pub struct Upload {
    pub id: u64,
    /// The browser's name for it (a label, shortened).
    pub name: String,
    pub bytes: usize,
    #[serde(skip)]
    path: PathBuf,
}

/// The uploads' folder's name starts with this, then the panel's pid and a dash: a
/// folder whose panel was killed (and so never removed it) is known by its pid.
const FOLDER_PREFIX: &str = "underfoot-panel-";

/// Removes the upload folders in `temp` of panels that are gone (killed before they could
/// remove them). A folder whose panel may be alive, or whose name has no pid, stays.
fn remove_stale_folders(temp: &Path) {
    let Ok(entries) = std::fs::read_dir(temp) else {
        return;
    };
    let own = std::process::id();
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name
            .to_str()
            .and_then(|n| n.strip_prefix(FOLDER_PREFIX))
            .and_then(|rest| rest.split_once('-'))
            .and_then(|(pid, _)| pid.parse::<u32>().ok())
        else {
            continue;
        };
        let is_dir = entry.file_type().is_ok_and(|t| t.is_dir());
        if is_dir && pid != own && underfoot::atomic_file::process_is_gone(pid) {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

/// The uploads, in a temporary folder removed when the panel ends.
pub struct Uploads {
    dir: tempfile::TempDir,
    files: Vec<Upload>,
    next: u64,
}

impl Uploads {
    pub fn new() -> anyhow::Result<Self> {
        remove_stale_folders(&std::env::temp_dir());
        let dir = tempfile::Builder::new()
            .prefix(&format!("{FOLDER_PREFIX}{}-", std::process::id()))
            .tempdir()
            .map_err(|e| anyhow::anyhow!("making the panel's temporary folder: {e}"))?;
        Ok(Self {
            dir,
            files: Vec::new(),
            next: 1,
        })
    }

    /// Stores `bytes` as a recording the browser called `name`.
    pub fn add(&mut self, name: &str, bytes: &[u8]) -> Result<Upload, String> {
        let ext = Path::new(name)
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .filter(|e| matches!(e.as_str(), "wav" | "flac" | "ogg" | "oga"))
            .ok_or_else(|| {
                format!(
                    "{}: not a recording this panel reads (WAV, FLAC or Ogg Vorbis: .wav, \
                     .flac, .ogg)",
                    truncate(name)
                )
            })?;
        if bytes.is_empty() {
            return Err(format!("{}: the file is empty", truncate(name)));
        }
        if self.files.len() >= MAX_FILES {
            return Err(format!(
                "already {MAX_FILES} recordings uploaded: fit them, then upload more"
            ));
        }
        let total: usize = self.files.iter().map(|f| f.bytes).sum();
        if total + bytes.len() > MAX_TOTAL {
            return Err(format!(
                "the uploads would exceed {} MiB in all: fit what is there first",
                MAX_TOTAL >> 20
            ));
        }
        let id = self.next;
        self.next += 1;
        let path = self.dir.path().join(format!("upload-{id}.{ext}"));
        std::fs::write(&path, bytes).map_err(|e| format!("storing the upload: {e}"))?;
        let upload = Upload {
            id,
            name: truncate(name).chars().take(120).collect(),
            bytes: bytes.len(),
            path,
        };
        self.files.push(upload.clone());
        Ok(upload)
    }

    /// The uploads `ids`, taken out of the list (their files are removed after the fit).
    fn take(&mut self, ids: &[u64]) -> Result<Vec<Upload>, String> {
        if ids.is_empty() {
            return Err("no recordings given: upload some first".into());
        }
        if let Some(missing) = ids
            .iter()
            .find(|id| !self.files.iter().any(|f| f.id == **id))
        {
            return Err(format!(
                "no upload {missing} (already fitted, or never uploaded)"
            ));
        }
        let (taken, kept) = std::mem::take(&mut self.files)
            .into_iter()
            .partition(|f| ids.contains(&f.id));
        self.files = kept;
        Ok(taken)
    }
}

/// Where a fit is.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "state", rename_all = "lowercase")]
pub enum JobState {
    Running {
        progress: String,
    },
    Done {
        progress: String,
        material: serde_json::Value,
        saved: String,
    },
    Failed {
        progress: String,
        error: String,
    },
}

/// The fits started from the page.
#[derive(Default)]
pub struct Jobs {
    next: AtomicU64,
    jobs: Mutex<Vec<(u64, Arc<Mutex<JobState>>)>>,
}

impl Jobs {
    /// The state of fit `id`.
    pub fn get(&self, id: u64) -> Option<JobState> {
        let jobs = self
            .jobs
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        jobs.iter().find(|(j, _)| *j == id).map(|(_, s)| {
            s.lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .clone()
        })
    }

    fn start(&self) -> (u64, Arc<Mutex<JobState>>) {
        let id = self.next.fetch_add(1, Ordering::Relaxed) + 1;
        let state = Arc::new(Mutex::new(JobState::Running {
            progress: "reading the recordings".into(),
        }));
        let mut jobs = self
            .jobs
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if jobs.len() >= MAX_JOBS {
            jobs.remove(0);
        }
        jobs.push((id, Arc::clone(&state)));
        (id, state)
    }
}

/// Starts fitting material `name` from uploads `ids`; the job's id.
pub fn start(shared: &Arc<Shared>, name: &str, ids: &[u64]) -> Result<u64, String> {
    validate_name(name).map_err(|e| format!("material name: {e}"))?;
    let uploads = shared
        .uploads
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .take(ids)?;
    let (id, state) = shared.jobs.start();
    let shared = Arc::clone(shared);
    let name = name.to_owned();
    std::thread::Builder::new()
        .name(format!("panel-fit-{id}"))
        .spawn(move || {
            let set = |s: JobState| {
                *state
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner) = s;
            };
            let progress = |text: String| set(JobState::Running { progress: text });
            let outcome = fit(&shared, &name, &uploads, &progress);
            for u in &uploads {
                let _ = std::fs::remove_file(&u.path);
            }
            set(match outcome {
                Ok((material, saved)) => JobState::Done {
                    progress: format!("{name}: fitted and added"),
                    material,
                    saved,
                },
                Err(e) => JobState::Failed {
                    progress: format!("{name}: failed"),
                    error: crate::message::chain(&e),
                },
            });
        })
        .map_err(|e| format!("starting the fit: {e}"))?;
    Ok(id)
}

/// The fit itself: the material's view for the page, and where it was saved.
fn fit(
    shared: &Shared,
    name: &str,
    uploads: &[Upload],
    progress: &dyn Fn(String),
) -> anyhow::Result<(serde_json::Value, String)> {
    // Checked before the slow part, as `fit` does: a broken library must not cost a fit.
    let paths: Vec<&Path> = uploads.iter().map(|u| u.path.as_path()).collect();
    // The library of the session the fit started in: a session started meanwhile with
    // another is not where the page said the fit would go.
    let library = shared.library();
    let library_out = match &library {
        Some(p) => {
            let out = OutputFile::check(p, &paths)?;
            Library::load_or_new(p)?;
            Some(out)
        }
        None => None,
    };
    let mut recordings = Vec::with_capacity(uploads.len());
    for u in uploads {
        let r = recording::read_for_analysis(&u.path, None)
            .map_err(|e| anyhow::anyhow!("{}: {e}", u.name))?;
        recordings.extend(r);
    }
    let cfg = BuildConfig::default();
    let mut tried = 0;
    let model = build_material(name, &recordings, &cfg, &mut |p| match p {
        Progress::Measured { strikes, .. } => {
            progress(format!("{strikes} strikes found; fitting the filter"));
        }
        Progress::OrderTried {
            order,
            lsd_db,
            nrmse,
            ..
        } => {
            tried += 1;
            progress(format!(
                "fitting: {tried} order(s) tried (last: order {order}, LSD {lsd_db:.2} dB, \
                 NRMSE {nrmse:.4})"
            ));
        }
        _ => {}
    })?;
    progress("checking: leave one recording out".into());
    let left_out = leave_one_out(&recordings, &cfg, &model)?;
    let odd = left_out
        .as_ref()
        .and_then(|l| crate::report::generalisation_warning(&model, l));
    let loo = left_out.as_ref().map(LeaveOneOutReport::of);
    // Prepared before anything is written: a material the engine cannot take fails the
    // fit with the library untouched. Once written, the fit is never reported failed.
    progress("preparing it for the engine".into());
    let (preparation, remote) = {
        let view = shared.session();
        (view.preparation.clone(), view.remote.clone())
    };
    let prepared = preparation.map(|p| p.prepare(&model)).transpose()?;
    let saved = match (&library_out, &library) {
        (Some(out), Some(path)) => {
            progress(format!("saving into {}", path.display()));
            let replaced = Library::edit(out, true, |library| {
                Ok(library.upsert(model.clone()).is_some())
            })?;
            format!(
                "{} {}",
                if replaced { "Replaced in" } else { "Added to" },
                path.display()
            )
        }
        _ => "Kept for this session only (start the panel with --library FILE to save fits)"
            .to_owned(),
    };
    let saved = match odd {
        Some(warning) => format!("{saved}. Warning: {warning}"),
        None => saved,
    };
    // Saved already: from here on, a session that is not running, or that ended
    // meanwhile, makes a note on the saved fit, not a failure.
    let slots = match (prepared, remote) {
        (Some((iir, physical)), Some(remote)) => {
            let slot = |m| -> anyhow::Result<u16> {
                remote
                    .send(RemoteCommand::Add(Box::new(m)))?
                    .ok_or_else(|| anyhow::anyhow!("the session gave no slot"))
            };
            slot(iir)
                .and_then(|iir| {
                    Ok(Slots {
                        iir,
                        physical: physical.map(slot).transpose()?,
                    })
                })
                .map_err(|e| format!("not playing now: {}", crate::message::chain(&e)))
        }
        _ => Err("the session is not running, so it does not play now".to_owned()),
    };
    match slots {
        Ok(slots) => {
            let entry = Entry {
                model,
                slots,
                added: true,
                leave_one_out: loo,
            };
            let json = entry.to_json();
            shared.session().add(entry);
            Ok((json, saved))
        }
        Err(why) => {
            let json = Entry {
                model,
                slots: Slots {
                    iir: 0,
                    physical: None,
                },
                added: true,
                leave_one_out: loo,
            }
            .to_json();
            Ok((json, format!("{saved}; {why}")))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_killed_panel_s_upload_folder_is_removed_and_a_live_one_kept() {
        let temp = tempfile::tempdir().unwrap();
        let make = |name: &str| {
            let dir = temp.path().join(name);
            std::fs::create_dir(&dir).unwrap();
            std::fs::write(dir.join("upload-1.ogg"), b"OggS").unwrap();
            dir
        };
        // No process has a pid this large (the kernel's maximum is 2^22).
        let killed = make("underfoot-panel-4194305-a1b2");
        let alive = make("underfoot-panel-1-c3d4");
        let own = make(&format!("underfoot-panel-{}-e5f6", std::process::id()));
        let unknown = make("underfoot-panel-g7h8");
        remove_stale_folders(temp.path());
        assert!(!killed.exists());
        assert!(alive.exists() && own.exists() && unknown.exists());
    }
}
