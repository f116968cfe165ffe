//! How far a part turns for its length: whole turns of bulky parts, measured.
//!
//! `cargo run --release -p rigidcells-tools --bin twist [DEGREES]` (default 720). Closed
//! cylinders of diameter 1 (`data_gen::cylinder`), their lowest tenth fixed and their highest
//! tenth turned by DEGREES about their axis, each solved by the library as `deform` solves it
//! (default parameters but the cell size): for a range of lengths at cells of 0.1, and for the
//! cylinder as long as it is wide at cell sizes from 0.3 to 0.05. Each row says whether the
//! turn held (the turn the cells carry from the fixed cells to the handle, load steps, halvings,
//! iterations) or how far it held before the solver refused it (`Error::TurnNotHeld`).

use std::time::Instant;

use rigidcells::Error;
use rigidcells::Silent;
use rigidcells::Vect;
use rigidcells::internal::pipeline::{self, Options};
use rigidcells::parse_spec;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let degrees: f64 = match std::env::args().nth(1) {
        Some(a) => a.parse()?,
        None => 720.0,
    };
    println!("turn asked {degrees}°; cylinders of diameter 1, the end tenths fixed and turned\n");
    println!("| height | turned span / diameter | cell size | cells | result | seconds |");
    println!("|---|---|---|---|---|---|");
    for height in [1.0, 2.0, 3.0, 5.0, 8.0] {
        row(height, 0.1, degrees)?;
    }
    for cell in [0.3, 0.2, 0.05] {
        row(1.0, cell, degrees)?;
    }
    Ok(())
}

/// One cylinder of `height` turned by `degrees` at cells of `cell`: a table row.
fn row(height: f64, cell: f64, degrees: f64) -> Result<(), Box<dyn std::error::Error>> {
    let mesh = data_gen::cylinder(0.5, height, 48, (24.0 * height) as usize);
    let points: Vec<Vect<3>> = mesh.vertices.iter().map(|v| Vect::<3>::from(*v)).collect();
    let text = format!(
        "[[fixed]]\nbox = {{ min = [-1, -1, -1], max = [1, 0.1, 1] }}\n\
         [[handle]]\nbox = {{ min = [-1, {}, -1], max = [1, {}, 1] }}\n\
         rotate = {{ axis = [0, 1, 0], degrees = {degrees} }}\n",
        height - 0.1,
        height + 1.0
    );
    let spec = parse_spec::<3>(&text, ".".as_ref(), "twist.toml".as_ref())?;
    let params = Options {
        cell_size: Some(cell),
        ..Default::default()
    }
    .params()
    .unwrap();
    let start = Instant::now();
    let result = pipeline::deform(&points, &mesh.triangles, &spec, &params, &Silent);
    let seconds = start.elapsed().as_secs_f64();
    let (cells, outcome) = match result {
        Ok((_, solution, info)) => {
            let s = &info.solver;
            let taken = s.turns.first().and_then(|t| t.taken_degrees);
            (
                solution.complex.len().to_string(),
                format!(
                    "held: {:.1}° carried, {} load steps, {} halvings, {} iterations",
                    taken.unwrap_or(f64::NAN),
                    s.load_steps,
                    s.halvings,
                    s.iterations
                ),
            )
        }
        Err(Error::TurnNotHeld(r)) => (
            "–".into(),
            format!("refused: gives way past {:.0}°", r.held_degrees),
        ),
        Err(e) => return Err(e.into()),
    };
    println!(
        "| {height} | {:.1} | {cell} | {cells} | {outcome} | {seconds:.1} |",
        height - 0.2
    );
    Ok(())
}
