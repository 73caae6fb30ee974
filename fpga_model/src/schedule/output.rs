//! The schedule written out: tiles assigned, placements in request order, what stays out,
//! the totals.

use super::*;

pub(super) fn assign_tiles(inp: &Inputs, st: &mut PlatformState, ws: &mut ScheduleWorkspace) {
    let Inputs {
        platform,
        catalogue,
        ..
    } = *inp;
    let vs = catalogue.variants();
    // Tiles: keep every part on a healthy tile that already holds it, then configure blank
    // tiles, then overwrite others (lowest index first).
    ws.taken.clear();
    ws.taken.resize(usize::from(platform.tiles), false);
    ws.pending.clear();
    ws.assigned.clear();
    for (k, &vi) in ws.choice.iter().enumerate() {
        let v = &vs[vi];
        for part in 0..v.tiles {
            let found = ws.healthy.iter().copied().find(|&t| {
                !ws.taken[usize::from(t)]
                    && st.tiles[usize::from(t)]
                        .bitstream
                        .as_deref()
                        .is_some_and(|b| is_tag(b, v, part))
            });
            match found {
                Some(t) => {
                    ws.taken[usize::from(t)] = true;
                    ws.assigned.push((k, t, false));
                }
                None => ws.pending.push((k, vi, part)),
            }
        }
    }
    for i in 0..ws.pending.len() {
        let (k, vi, part) = ws.pending[i];
        let free = |blank: bool| {
            ws.healthy.iter().copied().find(|&t| {
                !ws.taken[usize::from(t)] && st.tiles[usize::from(t)].bitstream.is_none() == blank
            })
        };
        let t = free(true)
            .or_else(|| free(false))
            .expect("search checked the tile count");
        ws.taken[usize::from(t)] = true;
        let v = &vs[vi];
        let slot = &mut st.tiles[usize::from(t)].bitstream;
        let mut s = match slot.take() {
            Some(mut s) => {
                s.clear();
                s
            }
            None => ws.string(),
        };
        let _ = write!(s, "{}/{}/{}#{part}", v.app, v.version, v.implementation);
        *slot = Some(s);
        ws.assigned.push((k, t, true));
    }
}

pub(super) fn write_placements(
    inp: &Inputs,
    active: &[Item],
    ws: &mut ScheduleWorkspace,
    out: &mut Schedule,
) {
    let Inputs {
        platform,
        catalogue,
        requests,
        ..
    } = *inp;
    let vs = catalogue.variants();
    let cores = platform.cpu_cores;
    // Placements in request order.
    ws.order.clear();
    ws.order.extend(0..active.len());
    ws.order.sort_unstable_by_key(|&k| active[k].req);
    for &k in &ws.order {
        let it = &active[k];
        let v = &vs[ws.choice[k]];
        let mut p = ws.spare_placements.pop().unwrap_or(Placement {
            app: String::new(),
            version: String::new(),
            implementation: v.implementation,
            support: v.support,
            tiles: Vec::new(),
            cpu_share: 0.0,
            ms_per_frame: 0.0,
            ms: Vec::new(),
            required_fps: 0.0,
            u_app: 0.0,
            reconfigured: Vec::new(),
        });
        set(&mut p.app, &requests[it.req].app);
        set(&mut p.version, &v.version);
        p.implementation = v.implementation;
        p.support = v.support;
        p.tiles.clear();
        p.reconfigured.clear();
        for &(kk, t, reconf) in &ws.assigned {
            if kk == k {
                p.tiles.push(t);
                if reconf {
                    p.reconfigured.push(t);
                }
            }
        }
        p.tiles.sort_unstable();
        p.reconfigured.sort_unstable();
        p.cpu_share = v.cpu_share_at(it.fps, cores);
        p.ms_per_frame = v.ms_per_frame();
        p.ms.clone_from(&v.ms);
        p.required_fps = it.fps;
        p.u_app = f64::from(v.tiles) + p.cpu_share;
        out.placements.push(p);
    }
}

/// The applications that gave way and found no room again: dropped, with what they lacked.
pub(super) fn drop_still_out(
    inp: &Inputs,
    room: Room,
    ws: &mut ScheduleWorkspace,
    out: &mut Schedule,
) {
    let Inputs {
        catalogue,
        requests,
        ..
    } = *inp;
    let vs = catalogue.variants();
    let cores = room.cores;
    let rank_text = |it: &Item| inp.rank_text(it);
    let placements = &out.placements;
    for i in 0..ws.still_out.len() {
        let item = ws.still_out[i];
        let app = &requests[item.req].app;
        let version = &vs[item.version].version;
        let others_tiles: u32 = placements
            .iter()
            .filter(|p| p.app != *app)
            .map(|p| p.tiles.len() as u32)
            .sum();
        let others_cpu: f64 = placements
            .iter()
            .filter(|p| p.app != *app)
            .map(|p| p.cpu_share)
            .sum();
        let mut d = ws.dropped(app, version);
        d.reason.push_str("insufficient resources (");
        why_not(
            &mut d.reason,
            catalogue,
            app,
            version,
            item.fps,
            room.tiles.saturating_sub(others_tiles),
            room.cpu - others_cpu,
            cores,
            &mut ws.impls,
        );
        let _ = write!(d.reason, "); {}", rank_text(&item));
        out.dropped.push(d);
    }
}

/// The totals of the schedule: load, power, tiles, reconfigurations, the summary line.
pub(super) fn write_totals(
    inp: &Inputs,
    st: &PlatformState,
    ws: &ScheduleWorkspace,
    out: &mut Schedule,
    online: u8,
    external: f64,
) {
    let Inputs {
        platform, policy, ..
    } = *inp;
    let cores = platform.cpu_cores;
    let placements = &out.placements;
    let tiles_used: u8 = placements.iter().map(|p| p.tiles.len() as u8).sum();
    let app_cpu_share: f64 = placements.iter().map(|p| p.cpu_share).sum();
    let reconfigurations: u32 = placements.iter().map(|p| p.reconfigured.len() as u32).sum();
    let cpu_load = if online == 0 {
        1.0
    } else {
        (app_cpu_share + external) * f64::from(cores) / f64::from(online)
    };
    out.summary.clear();
    if out.placements.is_empty() {
        out.summary.push('-');
    } else {
        let mut first = true;
        for m in out.placements.iter().flat_map(|p| p.ms.iter()) {
            if !first {
                out.summary.push_str(" + ");
            }
            first = false;
            let _ = write!(out.summary, "{}", FmtMs(*m));
        }
        out.summary.push_str(" ms");
    }
    set(&mut out.policy, &policy.name);
    out.cpu_load = cpu_load;
    out.app_cpu_share = app_cpu_share;
    out.external_cpu_load = external;
    out.cpu_cores_online = online;
    out.tiles_used = tiles_used;
    out.free_tiles = (ws.healthy.len() as u8).saturating_sub(tiles_used);
    out.failed_tiles.clear();
    out.failed_tiles.extend(
        st.tiles
            .iter()
            .enumerate()
            .filter(|(_, t)| t.failed)
            .map(|(i, _)| i as u8),
    );
    out.reconfigurations = reconfigurations;
    out.reconfiguration_ms = f64::from(reconfigurations) * platform.reconfiguration_ms_per_tile;
    out.power_w = platform.power_w(tiles_used, app_cpu_share + external);
}
