//! A STATUSTEXT flood from the autopilot costs nothing (issue 26 item 5): 11,653 link events in
//! one record made it too large to log, and 11 decision records were lost as `too_large`. Through
//! `fly`'s own cycle (`decide`, `finish_record`) and the decision log, every record of a flood is
//! written, with the flood summarised and its size counted.

use companion::decision_log::{
    DEFAULT_MAX_LINE_BYTES, DecisionLog, Header, WriterOptions, read_log,
};
use companion::fly::{self, Decider, FlyArgs, FlySetup, Shell};
use companion::params::default_params_dir;
use companion_core::mission::ActionCatalogue;
use companion_core::observations::Observations;
use companion_core::record::{DecisionRecord, LinkEvent, MAX_LINK_EVENTS, Plan};
use std::time::Duration;

/// Plans nothing: the flood, not the core, is under test.
struct Idle(ActionCatalogue);

impl Idle {
    fn new() -> Self {
        let files = companion::params::read_params_dir(&default_params_dir()).unwrap();
        Idle(ActionCatalogue::load(&files).unwrap())
    }
}

impl Decider for Idle {
    fn step(&mut self, _: &Observations) -> (Plan, DecisionRecord) {
        (Plan::default(), DecisionRecord::default())
    }
    fn actions(&self) -> &ActionCatalogue {
        &self.0
    }
    fn launch_verdict(
        &self,
        _: &DecisionRecord,
    ) -> Result<(), companion_core::launch::LaunchRefusal> {
        Err(companion_core::launch::LaunchRefusal::NoGuarantee) // idles: never starts
    }
}

const FLOOD: usize = 11_653;

fn flood(cycle: u64) -> Vec<LinkEvent> {
    (0..FLOOD)
        .map(|i| {
            LinkEvent::AutopilotText(format!(
                "PreArm: flood text number {i:05} of cycle {cycle:03}, padded out well past STATUSTEXT length"
            ))
        })
        .collect()
}

#[test]
fn a_statustext_flood_loses_no_decision_record() {
    // Without the cap, one cycle's flood is over the log's line limit by itself.
    let raw = serde_json::to_string(&flood(0)).unwrap();
    assert!(
        raw.len() as u64 > DEFAULT_MAX_LINE_BYTES,
        "{} bytes",
        raw.len()
    );

    let mut args =
        FlyArgs::from_cli(["--connect", "udpin:127.0.0.1:14550", "--auto-start"]).unwrap();
    args.params = Some(default_params_dir());
    let setup = FlySetup::load(&args).unwrap();
    let mut vehicle = setup.vehicle(Duration::from_secs(3));
    let mut shell = Shell::new(&setup);
    let dir = tempfile::tempdir().unwrap();
    let log = DecisionLog::start(
        dir.path(),
        Header::new("test", std::time::SystemTime::now()),
        WriterOptions::default(),
    )
    .unwrap();
    let cycles = 12u64;
    let mut idle = Idle::new();
    for c in 0..cycles {
        let now = Duration::from_secs(c);
        let d = fly::decide(&mut idle, &mut shell, &mut vehicle, || now);
        let mut transport = flood(c);
        let rec = fly::finish_record(d, &mut shell, &mut vehicle, c, &mut transport);
        assert!(log.record(rec));
    }
    let stats = log.close();
    assert_eq!(stats.records, cycles);
    assert_eq!((stats.dropped, stats.too_large), (0, 0));
    let read = read_log(dir.path()).unwrap();
    assert_eq!(read.records.len(), cycles as usize);
    for r in &read.records {
        assert_eq!(
            r.link_events.len(),
            MAX_LINK_EVENTS + 1,
            "cycle {}",
            r.cycle
        );
        let summary = r.link_events.last().unwrap().to_string();
        let more = FLOOD - MAX_LINK_EVENTS;
        assert!(
            summary.starts_with(&format!("({more} more link events since the last cycle")),
            "{summary}"
        );
    }
}
