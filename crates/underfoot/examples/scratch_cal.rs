use underfoot::physical::{calibrate, CalibrationConfig};
fn main() {
    let root = std::path::Path::new("../shared/data/footsteps");
    let only: Vec<String> = std::env::args().skip(1).collect();
    for m in ["dirt","glass","grass","gravel","hard","ice","metal","sand","snow","water","wood"] {
        if !only.is_empty() && !only.iter().any(|o| o==m) { continue; }
        let dir = root.join(m);
        let mut recs = vec![];
        for e in std::fs::read_dir(&dir).unwrap() { let p = e.unwrap().path(); if p.extension().map_or(false,|x| x=="ogg") { recs.push(underfoot::recording::read(&p, None).unwrap()); } }
        let t = std::time::Instant::now();
        match calibrate(&recs, &CalibrationConfig::default()) {
            Ok(model) => println!("{m}: {:?} modes {} lsd {:.2} nrmse {:.3} onsets {:.1} half {:.0}ms iso {} a {:.3} alpha {:.4} gain {:.3e} t {:.2}s",
                model.kind, model.modes.len(), model.record.lsd_db, model.record.nrmse, model.record.onsets_per_strike, model.record.half_energy_ms, model.record.isolated_impacts, model.record.rate_scale, model.events_per_newton, model.output_gain, t.elapsed().as_secs_f64()),
            Err(e) => println!("{m}: ERROR {e}"),
        }
    }
}
