//! The scheduler as it was before the reusable workspace (`schedule_into`), kept verbatim as
//! the independent answer the workspace path must reproduce on any input (tests/workspace.rs).
#![allow(dead_code)]

use fpga_model::{
    Catalogue, Degradation, Dropped, Placement, Platform, PlatformState, Request, ResourcePolicy,
    Schedule, Tile, Variant, fmt_ms,
};
use std::collections::BTreeSet;

const EPS: f64 = 1e-9;

/// A request the scheduler still tries to place.
#[derive(Debug, Clone)]
struct Item {
    req: usize,
    app: String,
    version: String,
    fps: f64,
    rank: usize,
}

/// What is left for applications: healthy tiles and CPU (fraction of nominal, after external).
#[derive(Debug, Clone, Copy)]
struct Room {
    tiles: u32,
    cpu: f64,
    cores: u8,
}

fn candidates<'c>(
    catalogue: &'c Catalogue,
    app: &str,
    version: &str,
    fps: f64,
) -> Vec<&'c Variant> {
    catalogue
        .implementations(app, version)
        .into_iter()
        .filter(|v| v.meets(fps))
        .collect()
}

/// First feasible assignment in lexicographic order (items by rank, implementations slowest
/// first). Being first means: no item could take a slower implementation with the others fixed.
fn search<'c>(catalogue: &'c Catalogue, items: &[Item], room: Room) -> Option<Vec<&'c Variant>> {
    let cands: Vec<Vec<&Variant>> = items
        .iter()
        .map(|it| candidates(catalogue, &it.app, &it.version, it.fps))
        .collect();
    let mut chosen = Vec::with_capacity(items.len());
    fn dfs<'c>(
        i: usize,
        cands: &[Vec<&'c Variant>],
        items: &[Item],
        room: Room,
        tiles: u32,
        cpu: f64,
        chosen: &mut Vec<&'c Variant>,
    ) -> bool {
        if i == cands.len() {
            return true;
        }
        for &v in &cands[i] {
            let t = tiles + u32::from(v.tiles);
            let share = v.cpu_share_at(items[i].fps, room.cores);
            let c = cpu + share;
            if t > room.tiles || (share > 0.0 && c > room.cpu + EPS) {
                continue;
            }
            chosen.push(v);
            if dfs(i + 1, cands, items, room, t, c, chosen) {
                return true;
            }
            chosen.pop();
        }
        false
    }
    dfs(0, &cands, items, room, 0, 0.0, &mut chosen).then_some(chosen)
}

/// Insert keeping rank order (ties by request order).
fn insert_ranked(items: &mut Vec<Item>, item: Item) -> usize {
    let pos = items
        .iter()
        .position(|x| (x.rank, x.req) > (item.rank, item.req))
        .unwrap_or(items.len());
    items.insert(pos, item);
    pos
}

/// Why no implementation of `app version` fits in what the other placements leave.
fn why_not(
    catalogue: &Catalogue,
    app: &str,
    version: &str,
    fps: f64,
    tiles_left: u32,
    cpu_left: f64,
    cores: u8,
) -> String {
    let mut out = Vec::new();
    for v in catalogue.implementations(app, version) {
        let i = v.implementation;
        if !v.meets(fps) {
            out.push(format!("{i} reaches only {:.1} fps", v.max_fps()));
            continue;
        }
        let share = v.cpu_share_at(fps, cores);
        if u32::from(v.tiles) > tiles_left {
            out.push(format!("{i} needs {} tiles ({tiles_left} free)", v.tiles));
        } else if share > 0.0 && share > cpu_left + EPS {
            out.push(format!(
                "{i} needs cpu {share:.3} ({:.3} left)",
                cpu_left.max(0.0)
            ));
        }
    }
    out.join("; ")
}

/// Decide placements for `requests` on `state` under `policy`. Returns the schedule and the
/// platform state after it (tile bitstreams updated; faults and loads unchanged).
pub(crate) fn reference_schedule(
    platform: &Platform,
    catalogue: &Catalogue,
    policy: &ResourcePolicy,
    state: &PlatformState,
    requests: &[Request],
) -> (Schedule, PlatformState) {
    let mut st = state.clone();
    st.tiles
        .resize(usize::from(platform.tiles), Tile::default());
    let cores = platform.cpu_cores;
    let online = st.cores_online.min(cores);
    let external = if st.external_cpu_load.is_nan() {
        1.0
    } else {
        st.external_cpu_load.max(0.0)
    };
    let healthy: Vec<u8> = (0..platform.tiles)
        .filter(|&i| !st.tiles[usize::from(i)].failed)
        .collect();
    let room = Room {
        tiles: healthy.len() as u32,
        cpu: platform.cpu_budget * f64::from(online) / f64::from(cores) - external,
        cores,
    };
    let n_ranked = policy.priority.len().max(1);

    let mut degraded = Vec::new();
    let mut dropped = Vec::new();
    let mut items = Vec::new();
    let mut seen = BTreeSet::new();
    for (req, r) in requests.iter().enumerate() {
        let drop = |reason: String| Dropped {
            app: r.app.clone(),
            version: r.version.clone(),
            reason,
        };
        if !catalogue.has_version(&r.app, &r.version) {
            dropped.push(drop(format!(
                "unknown variant {} {} (not in the catalogue)",
                r.app, r.version
            )));
            continue;
        }
        if !seen.insert(r.app.clone()) {
            dropped.push(drop(format!(
                "duplicate request: {} already requested this cycle",
                r.app
            )));
            continue;
        }
        if !(r.required_fps.is_finite() && r.required_fps > 0.0) {
            dropped.push(drop(format!(
                "invalid required rate {} fps",
                r.required_fps
            )));
            continue;
        }
        let mut version = r.version.clone();
        if candidates(catalogue, &r.app, &version, r.required_fps).is_empty() {
            let fastest = catalogue
                .implementations(&r.app, &r.version)
                .last()
                .map(|v| v.ms_per_frame())
                .unwrap_or(f64::INFINITY);
            let why = format!(
                "no implementation of {} {} reaches {:.1} fps (fastest {} ms per frame)",
                r.app,
                r.version,
                r.required_fps,
                fmt_ms(fastest)
            );
            match policy
                .degradation_path(&r.app, &r.version)
                .iter()
                .find(|v| !candidates(catalogue, &r.app, v, r.required_fps).is_empty())
            {
                Some(v) => {
                    degraded.push(Degradation {
                        app: r.app.clone(),
                        from: r.version.clone(),
                        to: v.clone(),
                        reason: why,
                    });
                    version = v.clone();
                }
                None => {
                    dropped.push(drop(why));
                    continue;
                }
            }
        }
        let rank = r
            .priority
            .map(|p| p as usize)
            .unwrap_or_else(|| policy.rank(&r.app));
        insert_ranked(
            &mut items,
            Item {
                req,
                app: r.app.clone(),
                version,
                fps: r.required_fps,
                rank,
            },
        );
    }

    // Resolve: while the set does not fit, the least important application first tries its
    // degradation path, then gives way.
    let mut active = items;
    let mut given_way: Vec<(Item, String)> = Vec::new();
    let mut choice = loop {
        if let Some(c) = search(catalogue, &active, room) {
            break c;
        }
        let last = active.pop().expect("the empty set always fits");
        let from = last.version.clone();
        let mut fixed = None;
        for v in policy.degradation_path(&last.app, &from) {
            if candidates(catalogue, &last.app, v, last.fps).is_empty() {
                continue;
            }
            active.push(Item {
                version: v.clone(),
                ..last.clone()
            });
            if let Some(c) = search(catalogue, &active, room) {
                fixed = Some((c, v.clone()));
                break;
            }
            active.pop();
        }
        let rank_text = format!(
            "policy {} ranks {} {} of {}",
            policy.name,
            last.app,
            last.rank + 1,
            n_ranked
        );
        if let Some((c, v)) = fixed {
            degraded.push(Degradation {
                app: last.app.clone(),
                from: from.clone(),
                to: v,
                reason: format!(
                    "insufficient resources to execute {} {} at {:.1} fps ({} healthy tiles, cpu headroom {:.3}); {}",
                    last.app,
                    from,
                    last.fps,
                    room.tiles,
                    room.cpu.max(0.0),
                    rank_text
                ),
            });
            break c;
        }
        given_way.push((last, rank_text));
    };

    // Re-place what now fits among those that gave way, most important first: dropping a more
    // important application may have freed room for a less important one.
    let mut still_out = Vec::new();
    for (item, rank_text) in given_way.into_iter().rev() {
        let mut versions = vec![item.version.clone()];
        versions.extend(
            policy
                .degradation_path(&item.app, &item.version)
                .iter()
                .cloned(),
        );
        let mut placed = false;
        for v in versions {
            if candidates(catalogue, &item.app, &v, item.fps).is_empty() {
                continue;
            }
            let pos = insert_ranked(
                &mut active,
                Item {
                    version: v.clone(),
                    ..item.clone()
                },
            );
            if let Some(c) = search(catalogue, &active, room) {
                if v != item.version {
                    degraded.push(Degradation {
                        app: item.app.clone(),
                        from: item.version.clone(),
                        to: v.clone(),
                        reason: format!(
                            "insufficient resources to execute {} {}; {rank_text}",
                            item.app, item.version
                        ),
                    });
                }
                choice = c;
                placed = true;
                break;
            }
            active.remove(pos);
        }
        if !placed {
            still_out.push((item, rank_text));
        }
    }

    // Tiles: keep every part on a healthy tile that already holds it, then configure blank
    // tiles, then overwrite others (lowest index first).
    let mut assigned: Vec<Vec<u8>> = vec![Vec::new(); active.len()];
    let mut reconf: Vec<Vec<u8>> = vec![Vec::new(); active.len()];
    let mut taken = BTreeSet::new();
    let mut pending = Vec::new();
    for (k, v) in choice.iter().enumerate() {
        for part in 0..v.tiles {
            let tag = format!("{}#{part}", v.key());
            match healthy.iter().find(|&&t| {
                !taken.contains(&t) && st.tiles[usize::from(t)].bitstream.as_deref() == Some(&tag)
            }) {
                Some(&t) => {
                    taken.insert(t);
                    assigned[k].push(t);
                }
                None => pending.push((k, tag)),
            }
        }
    }
    for (k, tag) in pending {
        let free = |blank: bool| {
            healthy.iter().copied().find(|t| {
                !taken.contains(t) && st.tiles[usize::from(*t)].bitstream.is_none() == blank
            })
        };
        let t = free(true)
            .or_else(|| free(false))
            .expect("search checked the tile count");
        taken.insert(t);
        st.tiles[usize::from(t)].bitstream = Some(tag);
        assigned[k].push(t);
        reconf[k].push(t);
    }

    let mut placements: Vec<(usize, Placement)> = active
        .iter()
        .zip(&choice)
        .enumerate()
        .map(|(k, (it, v))| {
            let mut tiles = assigned[k].clone();
            tiles.sort_unstable();
            let mut reconfigured = reconf[k].clone();
            reconfigured.sort_unstable();
            let cpu_share = v.cpu_share_at(it.fps, cores);
            (
                it.req,
                Placement {
                    app: it.app.clone(),
                    version: it.version.clone(),
                    implementation: v.implementation,
                    support: v.support,
                    tiles,
                    cpu_share,
                    ms_per_frame: v.ms_per_frame(),
                    ms: v.ms.clone(),
                    required_fps: it.fps,
                    u_app: f64::from(v.tiles) + cpu_share,
                    reconfigured,
                },
            )
        })
        .collect();
    placements.sort_by_key(|(req, _)| *req);
    let placements: Vec<Placement> = placements.into_iter().map(|(_, p)| p).collect();

    let tiles_used: u8 = placements.iter().map(|p| p.tiles.len() as u8).sum();
    let app_cpu_share: f64 = placements.iter().map(|p| p.cpu_share).sum();
    let reconfigurations: u32 = placements.iter().map(|p| p.reconfigured.len() as u32).sum();
    for (item, rank_text) in still_out {
        let others_tiles: u32 = placements
            .iter()
            .filter(|p| p.app != item.app)
            .map(|p| p.tiles.len() as u32)
            .sum();
        let others_cpu: f64 = placements
            .iter()
            .filter(|p| p.app != item.app)
            .map(|p| p.cpu_share)
            .sum();
        let detail = why_not(
            catalogue,
            &item.app,
            &item.version,
            item.fps,
            room.tiles.saturating_sub(others_tiles),
            room.cpu - others_cpu,
            cores,
        );
        dropped.push(Dropped {
            app: item.app.clone(),
            version: item.version.clone(),
            reason: format!("insufficient resources ({detail}); {rank_text}"),
        });
    }
    let cpu_load = if online == 0 {
        1.0
    } else {
        (app_cpu_share + external) * f64::from(cores) / f64::from(online)
    };
    let summary = if placements.is_empty() {
        "-".to_string()
    } else {
        let parts: Vec<String> = placements
            .iter()
            .flat_map(|p| p.ms.iter().map(|&m| fmt_ms(m)))
            .collect();
        format!("{} ms", parts.join(" + "))
    };
    let sched = Schedule {
        policy: policy.name.clone(),
        cpu_load,
        app_cpu_share,
        external_cpu_load: external,
        cpu_cores_online: online,
        tiles_used,
        free_tiles: (healthy.len() as u8).saturating_sub(tiles_used),
        failed_tiles: st.failed_tiles(),
        reconfigurations,
        reconfiguration_ms: f64::from(reconfigurations) * platform.reconfiguration_ms_per_tile,
        power_w: platform.power_w(tiles_used, app_cpu_share + external),
        degraded,
        dropped,
        summary,
        placements,
    };
    (sched, st)
}
