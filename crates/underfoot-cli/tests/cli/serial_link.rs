//! `underfoot run` on a serial port that hangs up: it exits with a clear message when
//! asked to, and otherwise waits at low CPU, lets the watchdog fade the output, and
//! reconnects when a device appears at the same path again.
#![cfg(target_os = "linux")]

use std::io::Read;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Mutex, PoisonError};
use std::thread;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};
use underfoot::sim::ReferenceSender;

/// Held while a pseudo-terminal is made and while a child is started: serialport opens
/// the master without close-on-exec, and a child that inherited another test's master
/// would keep that terminal up after the test closed its own end.
static SPAWN: Mutex<()> = Mutex::new(());

/// A pseudo-terminal whose slave is reachable at `link` (a symlink re-pointed each time).
fn pty_at(link: &Path) -> TTYPort {
    let _guard = SPAWN.lock().unwrap_or_else(PoisonError::into_inner);
    let (master, slave) = TTYPort::pair().expect("pseudo-terminal pair");
    // A close-on-exec duplicate, so that no child holds the terminal up after the test
    // closes the master (the hang-up under test).
    let mut master = master.try_clone_native().expect("duplicate the master");
    master.set_timeout(Duration::from_millis(20)).unwrap();
    let name = slave.name().expect("the slave end has a path");
    let tmp = link.with_extension("new");
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(name, &tmp).unwrap();
    std::fs::rename(&tmp, link).unwrap();
    // The master alone keeps the terminal up; the slave is opened by path by the child.
    drop(slave);
    master
}

fn spawn(args: &[&str]) -> Child {
    let _guard = SPAWN.lock().unwrap_or_else(PoisonError::into_inner);
    Command::new(crate::common::bin())
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start underfoot")
}

/// The child's CPU time (user + system, all threads), from /proc, in seconds.
fn cpu_of(child: &Child) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{}/stat", child.id())).unwrap();
    let after = stat.rsplit_once(')').unwrap().1;
    let f: Vec<&str> = after.split_whitespace().collect();
    (f[11].parse::<f64>().unwrap() + f[12].parse::<f64>().unwrap()) / 100.0
}

fn wait_for_exit(child: &mut Child, within: Duration) -> Option<std::process::ExitStatus> {
    let deadline = Instant::now() + within;
    while Instant::now() < deadline {
        if let Some(status) = child.try_wait().unwrap() {
            return Some(status);
        }
        thread::sleep(Duration::from_millis(20));
    }
    None
}

fn output_of(mut child: Child) -> (String, String) {
    let mut out = String::new();
    let mut err = String::new();
    child
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut out)
        .unwrap();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    let _ = child.wait();
    (out, err)
}

/// Sends `frames` force frames of `counts`, one every 10 ms.
fn send(sender: &mut ReferenceSender<TTYPort>, counts: &[u16], frames: usize) {
    for _ in 0..frames {
        let _ = sender.send_counts(counts);
        thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn run_exits_on_a_lost_serial_port_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("ttyLINK");
    let master = pty_at(&link);
    let input = format!("serial:{}", link.display());
    let mut child = spawn(&[
        "run",
        "--input",
        &input,
        "--output",
        "null",
        "--duration",
        "30",
        "--exit-on-disconnect",
    ]);
    thread::sleep(Duration::from_millis(1500));
    assert!(
        child.try_wait().unwrap().is_none(),
        "exited before the hang-up: {:?}",
        output_of(child)
    );
    let lost = Instant::now();
    drop(master);
    let status = wait_for_exit(&mut child, Duration::from_secs(5));
    let took = lost.elapsed();
    if status.is_none() {
        let _ = child.kill();
    }
    let (_, err) = output_of(child);
    let status = status.unwrap_or_else(|| panic!("still running 5 s after the hang-up: {err}"));
    assert!(!status.success(), "{err}");
    // Within the 5 s waited above: the fade-out and the report take a few hundred ms on an
    // idle machine.
    eprintln!("exited {took:?} after the hang-up");
    assert!(err.contains(&link.display().to_string()), "{err}");
    assert!(err.contains("lost") && err.contains("hung up"), "{err}");
    assert!(err.contains("--exit-on-disconnect"), "{err}");
}

#[test]
#[ignore = "slow tier: paced in real time"]
fn run_waits_for_a_lost_serial_port_at_low_cpu_and_reconnects() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("ttyLINK");
    let wav = dir.path().join("out.wav");
    let master = pty_at(&link);
    let input = format!("serial:{}", link.display());
    let output = format!("wav:{}", wav.display());
    let mut child = spawn(&[
        "run",
        "--input",
        &input,
        "--output",
        &output,
        "--duration",
        "9",
    ]);
    let start = Instant::now();
    thread::sleep(Duration::from_millis(1000));
    // A foot comes down and stays: 600 N on the heel, then the cable is pulled.
    let mut sender = ReferenceSender::new(master);
    send(&mut sender, &[0, 0], 10);
    send(&mut sender, &[1200, 0], 40);
    drop(sender);
    thread::sleep(Duration::from_millis(500));
    let (cpu0, t0) = (cpu_of(&child), Instant::now());
    thread::sleep(Duration::from_millis(2500));
    let (cpu1, t1) = (cpu_of(&child), Instant::now());
    let share = (cpu1 - cpu0) / t1.duration_since(t0).as_secs_f64();
    eprintln!(
        "run with its serial port lost: {:.1}% of a core",
        share * 100.0
    );
    // The device comes back at the same path; frames with no force (no new step).
    let master = pty_at(&link);
    let mut sender = ReferenceSender::new(master);
    while start.elapsed() < Duration::from_millis(8500) {
        send(&mut sender, &[0, 0], 10);
    }
    let status = wait_for_exit(&mut child, Duration::from_secs(10));
    if status.is_none() {
        let _ = child.kill();
    }
    let (out, err) = output_of(child);
    assert!(status.is_some_and(|s| s.success()), "{err}\n{out}");
    // Before the fix: 92% of a core. The bound leaves room for a loaded test machine; the
    // paced null/wav output alone uses a few percent.
    assert!(
        share < 0.10,
        "{:.1}% of a core while waiting",
        share * 100.0
    );
    assert!(err.contains("lost"), "{err}");
    assert!(err.contains("reconnected"), "{err}");
    assert!(
        out.contains("link: lost 1 time(s), reconnected 1 time(s)"),
        "{out}"
    );
    // 50 frames before the hang-up, more after the reconnection.
    let events: u64 = out
        .split("input: ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{out}"));
    assert!(events > 50, "no events after the reconnection: {out}");
    // The held force stopped arriving: the watchdog faded the output.
    assert!(!out.contains(" 0 watchdog fade(s)"), "{out}");
}
