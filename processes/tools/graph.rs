//! `afs graph`: the process graph of a stack as an SVG picture, drawn from the table of
//! services in `ipc::graph` (the boards, the supervisor, the link board and the clients as
//! boxes; one arrow per writer and reader, labelled with the services it carries).

use crate::ipc::graph::{EDGES, Edge, Party, Pattern};
use anyhow::{Context, Result};
use plotters::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

/// The picture's size (px).
const SIZE: (u32, u32) = (1250, 700);
/// A box's size (px).
const BOX: (i32, i32) = (230, 64);

/// Where each party's box sits (its top-left corner, px).
fn place(p: Party) -> (i32, i32) {
    match p {
        Party::Sensor => (435, 40),
        Party::Servo => (60, 320),
        Party::Estimator => (810, 320),
        Party::Supervisor => (435, 600),
        Party::Link => (810, 40),
        Party::Clients => (810, 600),
    }
}

fn centre(p: Party) -> (f64, f64) {
    let (x, y) = place(p);
    (
        f64::from(x) + f64::from(BOX.0) / 2.0,
        f64::from(y) + f64::from(BOX.1) / 2.0,
    )
}

/// Where the segment from the centre of `p` towards `to` leaves its box.
fn exit(p: Party, to: (f64, f64)) -> (f64, f64) {
    let (cx, cy) = centre(p);
    let (dx, dy) = (to.0 - cx, to.1 - cy);
    let (hw, hh) = (f64::from(BOX.0) / 2.0 + 4.0, f64::from(BOX.1) / 2.0 + 4.0);
    let t = (hw / dx.abs().max(1e-9)).min(hh / dy.abs().max(1e-9));
    (cx + t * dx, cy + t * dy)
}

/// The services each (writer, reader) pair shares, in the table's order. Not arrows: a
/// service that a party both writes and reads (the world blackboard, the link's batches), and
/// the clients' reads and writes but the supervisor's status (they may read any stream; their
/// box says so).
#[doc(hidden)]
pub fn arrows() -> BTreeMap<(Party, Party), Vec<&'static Edge>> {
    let mut out: BTreeMap<(Party, Party), Vec<&'static Edge>> = BTreeMap::new();
    for e in EDGES {
        for &a in e.from {
            for &b in e.to.iter().filter(|&&b| b != a) {
                let clients = a == Party::Clients || b == Party::Clients;
                if !clients || a == Party::Supervisor {
                    out.entry((a, b)).or_default().push(e);
                }
            }
        }
    }
    out
}

/// A service's label: its name, what it carries, `*` if only some set-ups open it.
fn label(e: &Edge) -> String {
    let how = match e.pattern {
        Pattern::Stream => "",
        Pattern::Request => ", request-response",
        Pattern::Blackboard => ", blackboard",
    };
    format!(
        "{} ({}{how}){}",
        e.service.trim_start_matches("afs/"),
        e.message,
        if e.optional { " *" } else { "" }
    )
}

/// Writes the picture to `path`.
pub fn render(path: &Path) -> Result<()> {
    let root = SVGBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let ink = RGBColor(40, 40, 40);
    let arrow_ink = RGBColor(31, 119, 180);
    for p in Party::ALL {
        let (x, y) = place(p);
        let fill = if p == Party::Clients {
            RGBColor(245, 245, 245)
        } else {
            RGBColor(225, 236, 247)
        };
        root.draw(&Rectangle::new(
            [(x, y), (x + BOX.0, y + BOX.1)],
            fill.filled(),
        ))?;
        root.draw(&Rectangle::new(
            [(x, y), (x + BOX.0, y + BOX.1)],
            ink.stroke_width(1),
        ))?;
        root.draw(&Text::new(
            p.label(),
            (x + 10, y + 12),
            ("sans-serif", 16).into_font().color(&ink),
        ))?;
        root.draw(&Text::new(
            p.role(),
            (x + 10, y + 38),
            ("sans-serif", 12).into_font().color(&ink),
        ))?;
    }
    let arrows = arrows();
    for (&(a, b), edges) in &arrows {
        // A pair with arrows both ways: each one shifted to its own side.
        let shift = if arrows.contains_key(&(b, a)) {
            9.0
        } else {
            0.0
        };
        let (ca, cb) = (centre(a), centre(b));
        let (dx, dy) = (cb.0 - ca.0, cb.1 - ca.1);
        let n = (dx * dx + dy * dy).sqrt().max(1e-9);
        let (ox, oy) = (-dy / n * shift, dx / n * shift);
        let s = exit(a, cb);
        let t = exit(b, ca);
        let (s, t) = ((s.0 + ox, s.1 + oy), (t.0 + ox, t.1 + oy));
        let px = |p: (f64, f64)| (p.0.round() as i32, p.1.round() as i32);
        root.draw(&PathElement::new(
            vec![px(s), px(t)],
            arrow_ink.stroke_width(2),
        ))?;
        let (ux, uy) = (dx / n, dy / n);
        let head = [
            t,
            (t.0 - 12.0 * ux + 5.0 * uy, t.1 - 12.0 * uy - 5.0 * ux),
            (t.0 - 12.0 * ux - 5.0 * uy, t.1 - 12.0 * uy + 5.0 * ux),
        ];
        root.draw(&Polygon::new(
            head.iter().map(|&p| px(p)).collect::<Vec<_>>(),
            arrow_ink.filled(),
        ))?;
        // The labels beside the arrow's middle, on its own side: to its right (or left) for
        // a steep arrow, above (or below) a flat one.
        let lines: Vec<String> = edges.iter().map(|e| label(e)).collect();
        let side = if shift > 0.0 { 1.0 } else { -1.0 };
        let (nx, ny) = (-uy * side, ux * side);
        let width = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0) as f64 * 6.0;
        let height = 14.0 * lines.len() as f64;
        // A third of the way from the writer: two arrows that cross in their middles keep
        // their labels apart.
        // The link board's long diagonals keep theirs in the middle.
        let f = if a == Party::Link || b == Party::Link {
            0.5
        } else {
            0.35
        };
        let mid = (s.0 + f * (t.0 - s.0), s.1 + f * (t.1 - s.1));
        let (left, top) = if nx.abs() >= ny.abs() {
            let x = if nx >= 0.0 {
                mid.0 + 8.0
            } else {
                mid.0 - 8.0 - width
            };
            (x, mid.1 - height / 2.0)
        } else {
            let y = if ny >= 0.0 {
                mid.1 + 6.0
            } else {
                mid.1 - 6.0 - height
            };
            (mid.0 - width / 2.0, y)
        };
        // Inside the picture.
        let left = left.clamp(4.0, f64::from(SIZE.0) - width - 4.0);
        for (i, l) in lines.iter().enumerate() {
            root.draw(&Text::new(
                l.clone(),
                px((left, top + 14.0 * i as f64)),
                ("sans-serif", 11).into_font().color(&arrow_ink),
            ))?;
        }
    }
    root.draw(&Text::new(
        "Services are named afs/<name>; * only in some set-ups: the insertion scenario, a link board, an estimator on another host",
        (60, 685),
        ("sans-serif", 12).into_font().color(&ink),
    ))?;
    root.present()
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
