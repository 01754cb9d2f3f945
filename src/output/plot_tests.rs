use super::*;

#[test]
fn ticks_fall_on_round_values_and_time_reads_as_a_clock() {
    assert_eq!(nice_step(0.93, 4), 0.5);
    assert_eq!(nice_step(0.4, 4), 0.1);
    assert_eq!(nice_step(2.6, 4), 1.0);
    assert_eq!(time_step(60.0, 8), 10.0);
    assert_eq!(time_step(3609.0, 8), 600.0);
    assert_eq!(clock(94.0), "1:34");
    assert_eq!(clock(3609.0), "1:00:09");
    assert_eq!(tick_label(-0.000001, 0.05), "0.00");
    assert_eq!(tick_label(1.5, 0.5), "1.5");
    assert_eq!(tick_label(2.0, 1.0), "2");
}

/// Dense decisions: the labels drawn never overlap in a lane, the rest are counted.
#[test]
fn decision_labels_never_overlap() {
    let series: Series = Default::default();
    let frame = Frame::new(TOP, 0.0, 600.0, &series, 0, 1.0);
    let marks: Vec<(u8, f64, Option<String>, String)> = (0..60)
        .map(|k| (1, 10.0 * k as f64, Some("m".into()), "changed loss".into()))
        .collect();
    let mut out = String::new();
    let hidden = frame.marks(&mut out, &marks, 1, "m");
    let mut lanes: std::collections::BTreeMap<String, Vec<(f64, f64)>> = Default::default();
    let mut labelled = 0;
    for line in out.lines().filter(|l| l.contains("<text")) {
        let attr = |name: &str| -> String {
            let at = line.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
            line[at..].split('"').next().unwrap().to_string()
        };
        let x: f64 = attr("x").parse().unwrap();
        let w = "changed loss".len() as f64 * LABEL_PX_PER_CHAR;
        let span = if attr("text-anchor") == "start" {
            (x, x + w)
        } else {
            (x - w, x)
        };
        lanes.entry(attr("y")).or_default().push(span);
        labelled += 1;
    }
    assert_eq!(labelled + hidden, 60);
    assert!(labelled >= 2 * LANES && hidden > 0);
    assert!(lanes.len() <= LANES);
    for spans in lanes.values_mut() {
        spans.sort_by(|a, b| a.0.total_cmp(&b.0));
        for w in spans.windows(2) {
            assert!(w[0].1 <= w[1].0, "{w:?}");
        }
    }
}

/// Merging keeps the envelope: a one-sample spike survives any number of merges.
#[test]
fn merged_buckets_keep_a_spike() {
    let mut b: Vec<Bucket> = (0..1024)
        .map(|k| {
            let v = if k == 517 { 0.2 } else { 1.0 };
            Bucket::new(k as f64, v, v - 0.1, v + 0.1)
        })
        .collect();
    for _ in 0..10 {
        merge_pairs(&mut b);
    }
    assert_eq!(b.len(), 1);
    assert_eq!((b[0].est_lo, b[0].est_hi), (0.2, 1.0));
    assert!((b[0].lo - 0.1).abs() < 1e-12 && (b[0].hi - 1.1).abs() < 1e-12);
    assert_eq!((b[0].t0, b[0].t1), (0.0, 1023.0));
}

/// The output panel: the set filter's guaranteed bounds where it has them (a gap where not
/// excited), the MIT-UKF's probable ones at the set's recent command.
#[test]
fn the_output_panel_holds_both_filters_bounds_at_the_recent_command() {
    let quad = crate::telemetry::Profile::resolve("quad-x").unwrap();
    let ukf = [AhcEstimate {
        gamma: 0.6,
        delta: 0.05,
        block: [1e-4, 0.0, 4e-4],
        ..AhcEstimate::default()
    }; 4];
    let mut set = [AhcEstimate {
        output_bounds: Some([-0.3, -0.2]),
        command_ref: 0.8,
        ..AhcEstimate::default()
    }; 4];
    set[1].output_bounds = None;
    let mut rec = PlotRecorder::default();
    rec.record(1.0, 1, &[&ukf, &ukf, &set], &quad);
    let sd = (0.64f64 * 1e-4 + 4e-4).sqrt();
    let centre = -0.4 * 0.8 + 0.05;
    for (j, (_, series)) in rec.traces.iter().enumerate() {
        let probable = series[0][2][0];
        assert!((probable.est_lo - centre).abs() < 1e-12);
        assert!((probable.lo - (centre - 3.0 * sd)).abs() < 1e-12);
        assert!((probable.hi - (centre + 3.0 * sd)).abs() < 1e-12);
        let guaranteed = series[1][2][0];
        if j == 1 {
            assert!(guaranteed.lo.is_nan() && guaranteed.hi.is_nan());
        } else {
            assert_eq!((guaranteed.lo, guaranteed.hi), (-0.3, -0.2));
        }
    }
    let svg = rec.render("t");
    assert_eq!(svg.matches("· output (γ-1)ū+δ").count(), 4);
}
