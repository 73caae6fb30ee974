//! Time exact inference on the exported health BNs in-process, for the side-by-side comparison
//! with pgmpy and pyAgrum (`bench/compare`).
//!
//! Reads the JSON written by `companion --example export_health_bn` (first argument), compiles
//! each manager's network once, then per repetition propagates one evidence set (cycling through
//! the sets, so the evidence changes between queries) and reads the query nodes' posteriors.
//! `times_ns` holds one `Instant` measurement around propagate + reads per query (warm engine).
//! Prints `{"managers":[{"name","posteriors":[[[p..]..]..],"times_ns":[..]}]}` where
//! `posteriors[e][q]` is the posterior of query node `q` under evidence set `e`.
//!
//! The crate has no JSON dependency, so a minimal JSON reader is included below.
//! Run: `cargo run --release -p bayes_net --example bench_bn -- health_bn.json [reps] [budget_s]`.
use bayes_net::{Evidence, NetworkBuilder, NodeId};
use std::collections::BTreeMap;
use std::hint::black_box;
use std::time::Instant;

#[derive(Debug, Clone)]
enum J {
    Null,
    Bool(bool),
    Num(f64),
    Str(String),
    Arr(Vec<J>),
    Obj(BTreeMap<String, J>),
}

impl J {
    fn get(&self, k: &str) -> &J {
        match self {
            J::Obj(m) => m.get(k).unwrap_or(&J::Null),
            _ => &J::Null,
        }
    }
    fn arr(&self) -> &[J] {
        match self {
            J::Arr(v) => v,
            _ => &[],
        }
    }
    fn str(&self) -> &str {
        match self {
            J::Str(s) => s,
            _ => "",
        }
    }
    fn num(&self) -> f64 {
        match self {
            J::Num(x) => *x,
            _ => f64::NAN,
        }
    }
}

struct P<'a> {
    b: &'a [u8],
    i: usize,
}

impl P<'_> {
    fn ws(&mut self) {
        while self.i < self.b.len() && self.b[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
    }
    fn val(&mut self) -> J {
        self.ws();
        match self.b[self.i] {
            b'{' => {
                self.i += 1;
                let mut m = BTreeMap::new();
                loop {
                    self.ws();
                    if self.b[self.i] == b'}' {
                        self.i += 1;
                        return J::Obj(m);
                    }
                    if self.b[self.i] == b',' {
                        self.i += 1;
                        continue;
                    }
                    let k = match self.val() {
                        J::Str(s) => s,
                        other => panic!("object key {other:?}"),
                    };
                    self.ws();
                    assert_eq!(self.b[self.i], b':');
                    self.i += 1;
                    let v = self.val();
                    m.insert(k, v);
                }
            }
            b'[' => {
                self.i += 1;
                let mut v = Vec::new();
                loop {
                    self.ws();
                    if self.b[self.i] == b']' {
                        self.i += 1;
                        return J::Arr(v);
                    }
                    if self.b[self.i] == b',' {
                        self.i += 1;
                        continue;
                    }
                    v.push(self.val());
                }
            }
            b'"' => {
                self.i += 1;
                let mut s = String::new();
                while self.b[self.i] != b'"' {
                    if self.b[self.i] == b'\\' {
                        self.i += 1;
                        s.push(match self.b[self.i] {
                            b'n' => '\n',
                            b't' => '\t',
                            c => c as char,
                        });
                        self.i += 1;
                    } else {
                        let start = self.i;
                        while self.b[self.i] != b'"' && self.b[self.i] != b'\\' {
                            self.i += 1;
                        }
                        s.push_str(std::str::from_utf8(&self.b[start..self.i]).unwrap());
                    }
                }
                self.i += 1;
                J::Str(s)
            }
            b't' => {
                self.i += 4;
                J::Bool(true)
            }
            b'f' => {
                self.i += 5;
                J::Bool(false)
            }
            b'n' => {
                self.i += 4;
                J::Null
            }
            _ => {
                let start = self.i;
                while self.i < self.b.len() && b"+-0123456789.eE".contains(&self.b[self.i]) {
                    self.i += 1;
                }
                let t = std::str::from_utf8(&self.b[start..self.i]).unwrap();
                J::Num(t.parse().unwrap_or_else(|_| panic!("number {t}")))
            }
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let text = std::fs::read_to_string(&args[1]).expect("read export");
    let reps: usize = args.get(2).map_or(10_000, |s| s.parse().unwrap());
    let budget: f64 = args.get(3).map_or(1.0, |s| s.parse().unwrap());
    let doc = P {
        b: text.as_bytes(),
        i: 0,
    }
    .val();
    let mut out = Vec::new();
    for m in doc.get("managers").arr() {
        let mut b = NetworkBuilder::new();
        for n in m.get("nodes").arr() {
            let states: Vec<&str> = n.get("states").arr().iter().map(J::str).collect();
            let parents: Vec<&str> = n.get("parents").arr().iter().map(J::str).collect();
            let cpt: Vec<f64> = n.get("cpt").arr().iter().map(J::num).collect();
            b.add_node(n.get("name").str(), &states, &parents, cpt);
        }
        let net = b.build().expect("valid network");
        let query: Vec<NodeId> = m
            .get("query")
            .arr()
            .iter()
            .map(|q| net.id(q.str()).expect("query node"))
            .collect();
        let sets: Vec<Evidence> = m
            .get("evidence")
            .arr()
            .iter()
            .map(|e| {
                let mut ev = Evidence::new();
                if let J::Obj(map) = e {
                    for (k, v) in map {
                        let id = net.id(k).expect("evidence node");
                        ev.set_state(id, net.state(id, v.str()).expect("state"));
                    }
                }
                ev
            })
            .collect();
        let mut engine = net.compile();
        let mut posteriors = String::from("[");
        for (i, ev) in sets.iter().enumerate() {
            engine.propagate(ev).expect("possible evidence");
            posteriors.push_str(if i == 0 { "[" } else { ",[" });
            for (j, q) in query.iter().enumerate() {
                let p: Vec<String> = engine
                    .marginal(*q)
                    .iter()
                    .map(|x| format!("{x:?}"))
                    .collect();
                posteriors.push_str(&format!(
                    "{}[{}]",
                    if j == 0 { "" } else { "," },
                    p.join(",")
                ));
            }
            posteriors.push(']');
        }
        posteriors.push(']');
        let mut times = Vec::with_capacity(reps);
        let mut spent = 0.0;
        let mut k = 0;
        while !sets.is_empty() && times.len() < reps && (times.len() < 3 || spent < budget) {
            let ev = &sets[k % sets.len()];
            k += 1;
            let t0 = Instant::now();
            engine.propagate(black_box(ev)).expect("possible evidence");
            let mut acc = 0.0;
            for q in &query {
                acc += engine.marginal(*q)[0];
            }
            black_box(acc);
            let dt = t0.elapsed();
            spent += dt.as_secs_f64();
            times.push(dt.as_nanos().to_string());
        }
        out.push(format!(
            "{{\"name\":\"{}\",\"posteriors\":{},\"times_ns\":[{}]}}",
            m.get("name").str(),
            posteriors,
            times.join(",")
        ));
    }
    println!("{{\"managers\":[{}]}}", out.join(","));
}
