fn main() -> anyhow::Result<()> {
    let sc = ugv_sim::Scenario::paper()?;
    let cfg =
        ugv_sim::mission::controller_config(&sc, ugv_controller::config::FollowerKind::Optimal);
    let t0 = std::time::Instant::now();
    let run = ugv_sim::sil::run_sil(sc.clone(), &cfg)?;
    let report = run.sim.report(run.outcome.clone());
    let v = ugv_sim::verdict::Verdict::judge("sil", &sc, report, Some(&run.trace));
    println!("{}", serde_json::to_string_pretty(&v)?);
    eprintln!("wall {:.2}s", t0.elapsed().as_secs_f64());
    ugv_sim::verdict::write_results(
        std::path::Path::new("/tmp/silres"),
        &sc,
        &v,
        &run.sim.trajectory,
        Some(&run.trace),
        cfg.perception.detection_radius,
    )?;
    Ok(())
}
