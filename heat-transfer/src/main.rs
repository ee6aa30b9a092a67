//! `heat-transfer [--seed N] [--json FILE] [--figures DIR] [--data DIR]`: thesis App. E on
//! the simulated air heater, each table printed beside the thesis's; `--json` writes the
//! numbers, `--figures` the figures (PNG), `--data` the E.2 experiments
//! as a `fes-dataset/2` data set.

use anyhow::{Context, bail};
use heat_transfer::control::{STEP, WINDUP};
use heat_transfer::{Report, study_with_figures};

const USAGE: &str = "usage: heat-transfer [--seed N] [--json FILE] [--figures DIR] [--data DIR]";

/// The command line.
struct Args {
    seed: u64,
    json: Option<String>,
    figures: Option<String>,
    data: Option<String>,
}

/// The command line: `None` for `--help`.
fn parse() -> anyhow::Result<Option<Args>> {
    let mut seed = 1;
    let mut json = None;
    let mut figures = None;
    let mut data = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seed" => seed = args.next().context("--seed needs a value")?.parse()?,
            "--json" => json = Some(args.next().context("--json needs a file")?),
            "--figures" => figures = Some(args.next().context("--figures needs a directory")?),
            "--data" => data = Some(args.next().context("--data needs a directory")?),
            "-h" | "--help" => return Ok(None),
            other => bail!("unknown argument `{other}`"),
        }
    }
    Ok(Some(Args {
        seed,
        json,
        figures,
        data,
    }))
}

fn main() -> anyhow::Result<()> {
    // Exit codes as every binary of the project: 2 for a command line not understood.
    let Args {
        seed,
        json,
        figures,
        data,
    } = match parse() {
        Ok(Some(a)) => a,
        Ok(None) => {
            println!("{USAGE}");
            return Ok(());
        }
        Err(e) => {
            eprintln!("heat-transfer: {e}\n{USAGE}");
            std::process::exit(2);
        }
    };
    if let Some(dir) = &data {
        heat_transfer::write_dataset(&sim_heat::HeatParams::default(), seed, dir.as_ref())
            .with_context(|| format!("--data {dir}"))?;
        println!("wrote the E.2 experiments (fes-dataset/2, seed {seed}) to {dir}");
    }
    let t0 = std::time::Instant::now();
    let report = study_with_figures(seed, figures.as_deref().map(std::path::Path::new))?;
    print_tables(&report);
    println!("\n(wall time {:.1} s)", t0.elapsed().as_secs_f64());
    if let Some(path) = json {
        let mut text = serde_json::to_string_pretty(&report)?;
        text.push('\n');
        std::fs::write(&path, text).with_context(|| format!("writing {path}"))?;
    }
    Ok(())
}

/// Prints thesis App. E's tables (Markdown), each beside the thesis's numbers.
fn print_tables(r: &Report) {
    print_table_e1(r);
    print_table_e2(r);
    print_tables_e3_e4(r);
    print_table_e5(r);
    print_fig_e6(r);
    print_scheduling_2d(r);
    print_orderings(r);
    print_fig_e8(r);
    print_control_gains(r);
    print_windup(r);
    print_fig_e7(r);
}

/// Prints Table E.1: the delays u -> y and alpha -> y per valve angle, beside the thesis's.
fn print_table_e1(r: &Report) {
    println!("## Table E.1: delays (samples of 50 ms), from the step responses\n");
    println!("| angle (deg) | u->y here | u->y thesis | alpha->y here | alpha->y thesis |");
    println!("|---:|---:|---:|---:|---:|");
    let thesis_alpha = ["4", "3", "3", "2", "< 1"];
    for (i, a) in ["20", "40", "60", "90", "120"].iter().enumerate() {
        println!(
            "| {a} | {} | {} | {} | {} |",
            r.delays_u_samples.get(*a).copied().unwrap_or_default(),
            r.delays_u_table_e1.get(*a).copied().unwrap_or_default(),
            r.delays_alpha_samples.get(*a).copied().unwrap_or_default(),
            thesis_alpha[i]
        );
    }
}

/// Prints Table E.2: the 1st-order ARX model of E.4.2 in prediction and in simulation mode.
fn print_table_e2(r: &Report) {
    let (p, s) = (&r.arx1.prediction, &r.arx1.simulation);
    println!("\n## Table E.2: 1st-order ARX, psi = [alpha(t-3), u(t-5), y(t-1)]\n");
    println!("| | prediction here | prediction thesis | simulation here | simulation thesis |");
    println!("|---|---:|---:|---:|---:|");
    println!(
        "| train MSE | {:.2e} | 5.30e-3 | {:.2e} | 4.35e-3 |",
        p.train_mse, s.train_mse
    );
    println!(
        "| test MSE | {:.2e} | 6.69e-3 | {:.2e} | 5.32e-3 |",
        p.test_mse, s.test_mse
    );
    println!(
        "| b alpha(t-3) | {:.4} | -0.0458 | {:.4} | -0.0697 |",
        p.b_alpha, s.b_alpha
    );
    println!(
        "| b u(t-5) | {:.4} | 0.0365 | {:.4} | 0.0537 |",
        p.b_u, s.b_u
    );
    println!("| pole | {:.3} | 0.945 | {:.3} | 0.911 |", p.pole, s.pole);
    println!("| d | {:.4} | 0.0292 | {:.4} | 0.0481 |", p.d, s.d);
    println!(
        "| G_alpha | {:.3} | -0.837 | {:.3} | -0.785 |",
        p.g_alpha, s.g_alpha
    );
    println!("| G_u | {:.3} | 0.667 | {:.3} | 0.605 |", p.g_u, s.g_u);
}

/// Prints Tables E.3-E.4: the 5- and 10-unit networks of E.4.3-E.4.4, local vs global.
fn print_tables_e3_e4(r: &Report) {
    let thesis_e3 = [
        ("4.96e-5", "1.80e-3", "1.79e-3", "1.28e-3", "1.27e-3"),
        ("5.34e-5", "1.87e-3", "1.91e-3", "2.17e-3", "1.78e-3"),
        ("4.88e-5", "1.74e-3", "1.88e-3", "1.10e-3", "1.50e-3"),
        ("5.12e-5", "1.77e-3", "1.82e-3", "1.29e-3", "1.54e-3"),
    ];
    println!(
        "\n## Tables E.3 (prediction-mode model) and E.4 (simulation-mode model); thesis in brackets\n"
    );
    println!(
        "| units | learning | train MSPE | train MSSE | test MSSE | sim. model train MSSE | sim. model test MSSE |"
    );
    println!("|---:|---|---:|---:|---:|---:|---:|");
    for (row, t) in r.learning.iter().zip(thesis_e3) {
        println!(
            "| {} | {} | {:.2e} ({}) | {:.2e} ({}) | {:.2e} ({}) | {:.2e} ({}) | {:.2e} ({}) |",
            row.units,
            row.learning,
            row.pred_train_mspe,
            t.0,
            row.pred_train_msse,
            t.1,
            row.pred_test_msse,
            t.2,
            row.sim_train_msse,
            t.3,
            row.sim_test_msse,
            t.4
        );
    }
}

/// Prints Table E.5: the state-space networks of E.4.5, general and restricted.
fn print_table_e5(r: &Report) {
    println!("\n## Table E.5: state-space networks (5 units, global learning, simulation mode)\n");
    println!("| model | train MSE | thesis | test MSE | thesis |");
    println!("|---|---:|---:|---:|---:|");
    for (row, t) in r
        .state_space
        .iter()
        .zip([("0.93e-3", "1.04e-3"), ("0.99e-3", "1.08e-3")])
    {
        println!(
            "| {} | {:.2e} | {} | {:.2e} | {} |",
            row.model, row.train_mse, t.0, row.test_mse, t.1
        );
    }
}

/// Prints Fig. E.6 as numbers: the state-space networks' eigenvector angles and eigenvalues.
fn print_fig_e6(r: &Report) {
    println!("\n## Fig. E.6: eigenvector angles (deg) and eigenvalues (1/s) per unit\n");
    println!("| model | unit | angle 1 | angle 2 | e1 | e2 |");
    println!("|---|---:|---:|---:|---:|---:|");
    for row in &r.state_space {
        for (i, (a, e)) in row.angles_rad.iter().zip(&row.eigenvalues).enumerate() {
            println!(
                "| {} | {i} | {:.1} | {:.1} | {:.2} | {:.2} |",
                row.model,
                a[0].to_degrees(),
                a[1].to_degrees(),
                e[0],
                e[1]
            );
        }
    }
}

/// Prints E.4.1, eq. E.1: the network over phi = \[alpha, u\] against the one over alpha.
fn print_scheduling_2d(r: &Report) {
    let t = &r.scheduling_2d;
    println!("\n## E.4.1, eq. E.1: phi = [alpha(t-3), u(t-5)], 3 x 3 tensor-product B-splines\n");
    println!("| network | train MSSE | test MSSE |");
    println!("|---|---:|---:|");
    if let Some(g5) = r.learning.first() {
        println!(
            "| 5 units over alpha (E.2) | {:.2e} | {:.2e} |",
            g5.sim_train_msse, g5.sim_test_msse
        );
    }
    println!(
        "| {} units over [alpha, u] (E.1) | {:.2e} | {:.2e} |",
        t.units, t.train_mse, t.test_mse
    );
}

/// Prints the orderings of the errors the thesis reports, under their JSON keys.
fn print_orderings(r: &Report) {
    println!("\n## Orderings\n");
    let o = &r.orderings;
    for (k, v) in [
        (
            "simulation_beats_prediction",
            Some(o.simulation_beats_prediction),
        ),
        (
            "global_beats_local_in_simulation",
            Some(o.global_beats_local_in_simulation),
        ),
        (
            "global_beats_local_in_simulation_test_10",
            Some(o.global_beats_local_in_simulation_test_10),
        ),
        (
            "prediction_local_bias_and_regularisation",
            Some(o.prediction_local_bias_and_regularisation),
        ),
        (
            "ten_units_generalise_worse",
            Some(o.ten_units_generalise_worse),
        ),
        ("restricted_close_to_general", o.restricted_close_to_general),
    ] {
        println!(
            "- {k}: {}",
            v.map_or("not computed".to_string(), |b| b.to_string())
        );
    }
}

/// Prints Fig. E.8 (E.4.7): the LCN against the linear controller on each of the three plants.
fn print_fig_e8(r: &Report) {
    for (title, c) in [
        ("Fig. E.8(a): control of the design model", &r.control),
        (
            "Fig. E.8(b): control of the E.4.4 model (alpha also an input)",
            &r.control_changed_plant,
        ),
        (
            "Control of the simulated process itself (noise-free)",
            &r.control_process,
        ),
    ] {
        println!("\n## {title}: reference {} -> {}\n", STEP.0, STEP.1);
        println!(
            "| controller | alpha | overshoot % | rise (s) | rise target (s) | steady error |"
        );
        println!("|---|---:|---:|---:|---:|---:|");
        for (name, ctl) in [("LCN", &c.lcn), ("linear (alpha = 0.5)", &c.linear)] {
            for s in [&ctl.small, &ctl.mid, &ctl.large] {
                println!(
                    "| {name} | {:.1} | {:.1} | {:.2} | {:.2} | {:.1e} |",
                    s.alpha, s.overshoot_pct, s.rise_s, s.rise_target_s, s.steady_error
                );
            }
        }
    }
}

/// Prints E.4.7's design model against the process: steady-state gains per alpha.
fn print_control_gains(r: &Report) {
    println!(
        "\n## E.4.7's design model against the process: steady-state gain over the step {} -> {}\n",
        STEP.0, STEP.1
    );
    println!("| alpha | model dy/dw | process dy/dw | process dy/du |");
    println!("|---:|---:|---:|---:|");
    for g in &r.control_gains {
        println!(
            "| {:.1} | {:.3} | {:.3} | {:.3} |",
            g.alpha, g.model, g.process, g.process_voltage
        );
    }
}

/// Prints the anti-reset-windup check: the LCN's settling after an unreachable reference.
fn print_windup(r: &Report) {
    println!(
        "\n## Anti-reset-windup (LCN, design model, alpha = 0.9): reference {} -> {} (unreachable) -> {}\n",
        WINDUP.0, WINDUP.1, WINDUP.2
    );
    println!(
        "settling within 0.01 after the return to {}: {:.2} s with, {:.2} s without",
        WINDUP.2, r.windup.with_s, r.windup.without_s
    );
}

/// Prints Fig. E.7 as numbers: the global simulation-mode networks frozen over phi.
fn print_fig_e7(r: &Report) {
    println!("\n## Fig. E.7: networks frozen over phi (global learning, simulation mode)\n");
    println!("| phi | G_u (5) | G_alpha (5) | pole (5) | G_u (10) | G_alpha (10) | pole (10) |");
    println!("|---:|---:|---:|---:|---:|---:|---:|");
    for (a, b) in r.static_5.iter().zip(&r.static_10).step_by(2) {
        println!(
            "| {:.1} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
            a.phi, a.g_u, a.g_alpha, a.pole, b.g_u, b.g_alpha, b.pole
        );
    }
}
