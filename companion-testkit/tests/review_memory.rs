//! `review` and `export` stream the log: the peak heap while reviewing a log stays a fraction
//! of the log's size, where reading the whole log (`read_log`) holds more than the file.
//! Measured with a counting global allocator (live bytes, peak), not with time.

use companion::decision_log::read_log;
use companion_testkit::synthetic;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(l) };
        if !p.is_null() {
            let now = LIVE.fetch_add(l.size(), Ordering::Relaxed) + l.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) };
        LIVE.fetch_sub(l.size(), Ordering::Relaxed);
    }
}

#[global_allocator]
static A: Counting = Counting;

/// Peak live heap above what was live when `f` started.
fn peak_during<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let out = f();
    (out, PEAK.load(Ordering::Relaxed) - base)
}

#[test]
fn review_holds_bounded_state_not_the_log() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("decisions.jsonl");
    {
        use std::io::Write;
        let one = synthetic::mission(100);
        let mut f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        writeln!(
            f,
            "{{\"kind\":\"header\",\"schema\":1,\"command\":\"companion simulate\"}}"
        )
        .unwrap();
        for i in 0..16_000u64 {
            let mut r = one[(i % 100) as usize].clone();
            r.cycle = i;
            r.time_s = i as f64;
            serde_json::to_writer(&mut f, &r).unwrap();
            writeln!(f).unwrap();
        }
        writeln!(f, "{{\"kind\":\"end\"}}").unwrap();
    }
    let size = std::fs::metadata(&path).unwrap().len() as usize;
    let (rev, review_peak) = peak_during(|| companion::review::review_path(&path, None).unwrap());
    assert_eq!(rev.summary.records, 16_000);
    drop(rev);
    let (whole, read_peak) = peak_during(|| read_log(&path).unwrap());
    assert_eq!(whole.records.len(), 16_000);
    drop(whole);
    eprintln!("log {size} bytes; review peak {review_peak} bytes; read_log peak {read_peak} bytes");
    // The whole-log reader holds at least the log's size: the measurement sees what it should.
    assert!(read_peak > size, "read_log {read_peak} vs log {size}");
    assert!(review_peak < size / 2, "review {review_peak} vs log {size}");
}
