use companion::guarantee::*;
use std::path::Path;

fn params() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../params"))
}

#[test]
fn print_patrolling() {
    println!("{}", check_text(params(), "patrolling").unwrap());
}
