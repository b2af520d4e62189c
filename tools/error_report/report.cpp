#include "tools/error_report/report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

namespace fovea::tools {

std::vector<AcuityFloor> acuityFloors(const std::vector<double>& floors_mm, const std::vector<double>& noise_floors_mm) {
  std::vector<AcuityFloor> floors;
  for (double mm : floors_mm) floors.push_back({mm * 1e-3, 0.0});
  for (double mm : noise_floors_mm) floors.push_back({0.0, mm * 1e-3});
  return floors;
}

std::string configName(const pipeline::AcuityConfig& a, std::string_view after_margin) {
  std::string name(pipeline::presetName(a.preset));
  if (a.preset == pipeline::Preset::kAcuity) {
    char part[48];
    std::snprintf(part, sizeof part, " k=%.2f", a.level_margin);
    name += part;
    if (a.refine_passes > 0) {
      std::snprintf(part, sizeof part, " refined %d", a.refine_passes);
      name += part;
    }
    name += after_margin;
    if (a.floor_m > 0.0) {
      std::snprintf(part, sizeof part, " floor %gmm", a.floor_m * 1e3);
      name += part;
    }
    if (a.floor_per_m2 > 0.0) {
      std::snprintf(part, sizeof part, " floor %gmm*r^2", a.floor_per_m2 * 1e3);
      name += part;
    }
    if (a.view_cull != pipeline::ViewCull::kOff) name += " cull " + std::string(pipeline::viewCullName(a.view_cull));
  }
  return name;
}

std::string formatFixed(double v, int precision, const char* missing) {
  if (std::isnan(v)) return missing;
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*f", precision, v);
  return buffer;
}

namespace {

std::string fixed(double v, int precision, const char* missing = "-") { return formatFixed(v, precision, missing); }

// Shortest round-trip-ish form for the CSV; empty for NaN.
std::string csvNumber(double v) {
  if (std::isnan(v)) return "";
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.9g", v);
  return buffer;
}

std::string percent(double share) { return fixed(100.0 * share, 1) + " %"; }

std::string eccBand(const RegionSummary& r) {
  if (r.index >= 0 && std::isnan(r.ecc_max_deg)) return "own";  // ACUITY's levels: each point at its own
  if (r.index <= 0) return r.index < 0 ? "all" : "0-" + fixed(r.ecc_max_deg, 0);
  if (r.ecc_max_deg >= 180.0) return "> " + fixed(r.ecc_min_deg, 0);
  return fixed(r.ecc_min_deg, 0) + "-" + fixed(r.ecc_max_deg, 0);
}

// Share above MAR over every region but the fovea, pooled.
double peripheralShare(const ConfigSummary& c) {
  uint64_t seen = 0, above = 0;
  for (const RegionSummary& r : c.regions) {
    if (r.index == 0) continue;
    seen += r.seen;
    above += static_cast<uint64_t>(std::llround(r.share_above_mar * static_cast<double>(r.seen)));
  }
  return seen ? static_cast<double>(above) / static_cast<double>(seen) : std::nan("");
}

Status writeFile(const std::string& path, const std::string& text) {
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  if (!file) return {ErrorCode::kIoError, path + ": cannot open for writing"};
  file << text;
  file.close();
  if (!file) return {ErrorCode::kIoError, path + ": write failed"};
  return Status::ok();
}

}  // namespace

Status writeCsv(const std::string& path, const std::vector<ConfigSummary>& configs) {
  std::ostringstream out;
  out << "preset,m,region,region_name,ecc_min_deg,ecc_max_deg,frames,voxel_mm,points_in,points_out,bytes_per_frame,raw_bytes_per_frame,"
         "time_ms_median,time_ms_p90,wall_ms_median,rms_mm,max_mm,rms_over_voxel,max_over_voxel,points_seen,share_above_mar,share_above_reference_mar,"
         "ratio_median,ratio_p95,ratio_max,ratio_median_first_deg,ratio_median_last_deg,share_above_mar_true_surface,"
         "ratio_p95_true_surface\n";
  for (const ConfigSummary& c : configs) {
    auto row = [&](const RegionSummary& r) {
      const bool all = r.index < 0;
      out << c.preset << ',' << csvNumber(c.slope) << ',' << (all ? std::string("all") : std::to_string(r.index))
          << ',' << r.name << ',' << csvNumber(r.ecc_min_deg) << ',' << csvNumber(r.ecc_max_deg) << ',' << c.frames
          << ',' << csvNumber(r.voxel_mm) << ',' << csvNumber(r.points_in) << ',' << csvNumber(r.points_out) << ','
          << csvNumber(r.wire_bytes) << ',' << csvNumber(r.points_out * kRawBytesPerPoint) << ',' << (all ? csvNumber(c.time_ms_median) : "") << ','
          << (all ? csvNumber(c.time_ms_p90) : "") << ',' << (all ? csvNumber(c.wall_ms_median) : "") << ','
          << csvNumber(r.rms_mm) << ',' << csvNumber(r.max_mm) << ','
          << csvNumber(r.rms_over_voxel) << ',' << csvNumber(r.max_over_voxel) << ',' << r.seen << ','
          << csvNumber(r.share_above_mar) << ',' << csvNumber(r.share_above_reference_mar) << ','
          << csvNumber(r.ratio_median) << ',' << csvNumber(r.ratio_p95) << ','
          << csvNumber(r.ratio_max) << ',' << csvNumber(r.ratio_first_deg) << ',' << csvNumber(r.ratio_last_deg) << ','
          << (all && c.have_truth ? csvNumber(c.truth.share_above_mar) : "") << ','
          << (all && c.have_truth ? csvNumber(c.truth.ratio_p95) : "") << '\n';
    };
    for (const RegionSummary& r : c.regions) row(r);
    row(c.all);
  }
  return writeFile(path, out.str());
}

Status writeMarkdown(const std::string& path, const ReportContext& context, const std::vector<ConfigSummary>& configs,
                     bool have_plot) {
  std::ostringstream md;
  md << "# Speed against error of the foveation (issue 3)\n\n"
     << "Generated by `fovea-error-report` (" << context.date_utc << "):\n\n"
     << "```sh\n" << context.command_line << "\n```\n\n"
     << "- camera: " << context.camera << "; gaze: " << context.gaze << "\n"
     << "- " << context.frames << " frames; every configuration foveates the same frames, side by side in this run\n"
     << "- host: " << context.host << "\n"
     << "- the camera's pixel pitch at the image centre: " << fixed(context.pixel_pitch_arcmin, 1)
     << " arcmin (seen from the camera), against MAR0 = 1 arcmin\n"
     << "- **bytes**: what the frame costs on the wire with fovea's chunk codec (net/codec.h at its defaults: 1 mm "
        "steps in the fovea, 1/8 of the voxel elsewhere, exact colour, 1200-byte datagrams, framing and "
        "authentication tag included; docs/protocol-chunks.md). The CSV also gives the raw payload, "
     << fixed(kRawBytesPerPoint, 0) << " bytes per output point (x, y, z float + r, g, b uchar)\n"
     << "- **time**: per frame, back-projection + partition + fixation + voxel sampling with the **scalar reference** "
        "kernels (the specification; the SIMD set is about 2.4x faster, bench/README.md), one thread; capture, "
        "encoding and the error computation are not included. *CPU time* is the "
        "thread's CPU time (median and p90 over the frames): other processes on a shared host do not inflate it. "
        "*wall* is the wall-clock median. Times vary from run to run and machine to machine\n"
     << "- **geometric error**: distance from each input point P to its representative R (the output point that "
        "stands for it: itself in the fovea, its voxel's centroid elsewhere); RMS pooled over all points of all frames, "
        "max over all frames; `/ v` divides by the region's voxel size (at most sqrt(3) = 1.73, since P and R share a "
        "voxel)\n"
     << "- **perceptual error**: alpha = angle between P - H and R - H (H the eye), compared with MAR(ecc(P)) = m ecc + "
        "1/60 degrees (Eq. 1) at P's own eccentricity. *above MAR* is the share of points with alpha > MAR(ecc(P)); "
        "alpha/MAR is summarised by its median, 95th percentile (median over frames of each frame's value) and max. "
        "Below 1 the displacement is finer than the eye resolves there (over-sampling); above 1 it is visible. "
        "Points with P or R at the eye have no angle and are left out (see README.md). The MAR is each "
        "configuration's own (its m); *m = " << fixed(context.reference_slope, 3) << " eye* judges every "
        "configuration by one fixed observer instead\n\n";

  if (have_plot) {
    md << "![bytes and time against error](report.png)\n\n";
  } else {
    md << "(No plot: gnuplot was not found. `cd` here and run `gnuplot report.gp` to draw report.png.)\n\n";
  }

  const bool any_truth = std::any_of(configs.begin(), configs.end(), [](const ConfigSummary& c) { return c.have_truth; });
  md << "## Per configuration\n\n";
  if (any_truth) {
    md << "*true surface*: the same displacements measured from where each input point really is (the camera's "
          "noiseless twin, same pixel) rather than from its noisy reading: sensor noise that the output keeps is "
          "error there, noise that a voxel averages away is not. alpha/MAR p95: median over frames of each frame's "
          "95th percentile.\n\n";
  }
  md << "| preset | m | points out | kept | bytes / frame | CPU time / frame [ms] median (p90) | wall [ms] median | RMS [mm] | max [mm] | "
        "above MAR, all points | alpha/MAR p95 | above MAR, outside the fovea | above MAR of the m = " << fixed(context.reference_slope, 3)
     << " eye | d0 [m] |" << (any_truth ? " above MAR, true surface | alpha/MAR p95, true surface |" : "") << "\n"
     << "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|" << (any_truth ? "---:|---:|" : "") << "\n";
  for (const ConfigSummary& c : configs) {
    const double kept = c.all.points_in > 0 ? c.all.points_out / c.all.points_in : 0.0;
    md << "| " << c.preset << " | " << fixed(c.slope, 3) << " | " << fixed(c.all.points_out, 0) << " | "
       << percent(kept) << " | " << fixed(c.bytesPerFrame() / 1e6, 3) << " MB | " << fixed(c.time_ms_median, 2)
       << " (" << fixed(c.time_ms_p90, 2) << ") | " << fixed(c.wall_ms_median, 2) << " | " << fixed(c.all.rms_mm, 2) << " | " << fixed(c.all.max_mm, 1)
       << " | " << percent(c.all.share_above_mar) << " | " << fixed(c.all.ratio_p95, 2) << " | "
       << (c.regions.size() > 1 ? percent(peripheralShare(c)) : std::string("-")) << " | "
       << percent(c.all.share_above_reference_mar) << " | " << (c.regions.size() > 1 && !std::isnan(c.d0_median_m) ? fixed(c.d0_median_m, 3) : std::string("-")) << " |";
    if (any_truth) {
      md << " " << (c.have_truth ? percent(c.truth.share_above_mar) : std::string("-")) << " | "
         << (c.have_truth ? fixed(c.truth.ratio_p95, 2) : std::string("-")) << " |";
    }
    md << "\n";
  }

  md << "\n## Per region\n\n"
     << "Points are means per frame; ecc is the region's eccentricity band in degrees; v its voxel size (mean over "
        "frames).\n\n"
     << "| preset | m | region | ecc [deg] | v [mm] | points in > out | RMS [mm] | max [mm] | RMS / v | max / v | "
        "above MAR | above MAR, m = " << fixed(context.reference_slope, 3) << " eye | alpha/MAR median | p95 | max |\n"
     << "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const ConfigSummary& c : configs) {
    for (const RegionSummary& r : c.regions) {
      md << "| " << c.preset << " | " << fixed(c.slope, 3) << " | " << r.name << " | " << eccBand(r) << " | "
         << (r.voxel_mm > 0.0 ? fixed(r.voxel_mm, 2) : std::string("-")) << " | " << fixed(r.points_in, 0) << " > "
         << fixed(r.points_out, 0) << " | " << fixed(r.rms_mm, 2) << " | " << fixed(r.max_mm, 1) << " | "
         << fixed(r.rms_over_voxel, 2) << " | " << fixed(r.max_over_voxel, 2) << " | " << percent(r.share_above_mar)
         << " | " << percent(r.share_above_reference_mar) << " | " << fixed(r.ratio_median, 2) << " | " << fixed(r.ratio_p95, 2) << " | " << fixed(r.ratio_max, 1)
         << " |\n";
    }
  }

  md << "\n## Steps at region borders\n\n"
     << "Median alpha/MAR of the points within 1 degree inside a border (the inner region's last degree) and within 1 "
        "degree outside it (the outer region's first degree). MAR is continuous across the border, so the ratio of the "
        "two is the step in displacement angle the eye sees there. The fovea is untouched (alpha = 0). *voxel ratio* is "
        "the step the voxel sizes make there, v_outside / v_inside = MAR(E_outside) / MAR(E_inside) (Eq. 6).\n\n"
     << "| preset | m | border [deg] | inside (region) | outside (region) | step | voxel ratio |\n"
     << "|---|---|---:|---:|---:|---:|---:|\n";
  for (const ConfigSummary& c : configs) {
    // ACUITY's levels have no eccentricity borders (each point is on its own level).
    if (!c.regions.empty() && std::isnan(c.regions[0].ecc_max_deg)) continue;
    for (std::size_t j = 0; j + 1 < c.regions.size(); ++j) {
      const RegionSummary& inner = c.regions[j];
      const RegionSummary& outer = c.regions[j + 1];
      const double in_ratio = j == 0 ? 0.0 : inner.ratio_last_deg;
      const double out_ratio = outer.ratio_first_deg;
      std::string step = "-";
      if (in_ratio > 0.0 && !std::isnan(out_ratio)) step = "x " + fixed(out_ratio / in_ratio, 1);
      if (in_ratio == 0.0 && out_ratio > 0.0) step = "from 0";
      const std::string voxel_ratio = inner.voxel_mm > 0.0 ? "x " + fixed(outer.voxel_mm / inner.voxel_mm, 1) : "-";
      md << "| " << c.preset << " | " << fixed(c.slope, 3) << " | " << fixed(inner.ecc_max_deg, 0) << " | "
         << fixed(in_ratio, 2) << " (" << inner.name << ") | " << fixed(out_ratio, 2) << " (" << outer.name << ") | "
         << step << " | " << voxel_ratio << " |\n";
    }
  }

  // Observations that follow from the numbers alone; the interpretation is in README.md.
  md << "\n## What the numbers say, region by region\n\n"
     << "For each foveated region, from alpha/MAR: *below MAR* when even its 95th percentile is below 1 (the eye "
        "cannot tell the displacements: the region is over-sampled, it could be thinned further); *mostly below* when "
        "the median is below 1 but the 95th percentile above; *above MAR* when the median is above 1 (most "
        "displacements are visible).\n\n";
  for (const ConfigSummary& c : configs) {
    if (c.regions.size() < 2) continue;
    md << "- " << c.preset << ", m " << fixed(c.slope, 3) << ":";
    for (std::size_t j = 1; j < c.regions.size(); ++j) {
      const RegionSummary& r = c.regions[j];
      if (r.seen == 0) {
        md << (j > 1 ? ";" : "") << " " << r.name << " empty";
        continue;
      }
      const char* verdict = r.ratio_p95 < 1.0 ? "below MAR" : r.ratio_median < 1.0 ? "mostly below MAR" : "above MAR";
      md << (j > 1 ? ";" : "") << " " << r.name << " " << verdict << " (median " << fixed(r.ratio_median, 2)
         << "x, p95 " << fixed(r.ratio_p95, 2) << "x MAR, " << percent(r.share_above_mar) << " of points above)";
    }
    md << "\n";
  }
  md << context.extra_markdown;
  if (!context.date_utc.empty()) md << "\n";
  return writeFile(path, md.str());
}

Status writePlotFiles(const std::string& data_path, const std::string& script_path, const ReportContext& context,
                      const std::vector<ConfigSummary>& configs) {
  std::vector<double> slopes;
  for (const ConfigSummary& c : configs) {
    if (std::find(slopes.begin(), slopes.end(), c.slope) == slopes.end()) slopes.push_back(c.slope);
  }
  // A gnuplot index block per slope for the paper's presets and, when there are
  // any, one for the ACUITY rows (labelled by their margin): each joined by its own line.
  const auto is_acuity = [](const ConfigSummary& c) { return c.preset.rfind("ACUITY", 0) == 0; };
  const bool any_acuity = std::any_of(configs.begin(), configs.end(), is_acuity);
  const int families = any_acuity ? 2 : 1;
  std::ostringstream data;
  data << "# label m bytes_per_frame_MB cpu_time_ms_median rms_mm share_above_mar_percent points_out "
          "share_above_reference_mar_percent\n";
  for (std::size_t s = 0; s < slopes.size(); ++s) {
    for (int family = 0; family < families; ++family) {
      if (s > 0 || family > 0) data << "\n\n";  // a new gnuplot index block
      data << "# m " << csvNumber(slopes[s]) << (family == 0 ? ", the paper's presets" : ", ACUITY") << "\n";
      for (const ConfigSummary& c : configs) {
        if (c.slope != slopes[s] || is_acuity(c) != (family == 1)) continue;
        const std::string label = family == 1 ? c.preset.substr(std::string("ACUITY ").size()) : c.preset;
        data << '"' << label << "\" " << csvNumber(c.slope) << ' ' << csvNumber(c.bytesPerFrame() / 1e6) << ' '
             << csvNumber(c.time_ms_median) << ' ' << csvNumber(c.all.rms_mm) << ' '
             << csvNumber(100.0 * c.all.share_above_mar) << ' ' << csvNumber(c.all.points_out) << ' '
             << csvNumber(100.0 * c.all.share_above_reference_mar) << "\n";
      }
    }
  }
  if (Status s = writeFile(data_path, data.str()); !s) return s;

  std::string data_name = data_path.substr(data_path.find_last_of('/') + 1);
  std::ostringstream gp;
  gp << "# Draws report.png from " << data_name << "; written by fovea-error-report. Run: gnuplot report.gp\n"
     << "set terminal pngcairo size 1500,620 font 'sans,11'\n"
     << "set output 'report.png'\n"
     << "set multiplot layout 1,2 title \"fovea: bytes and time against error, " << context.camera << ", "
     << context.frames << " frames (scalar reference)\"\n"
     << "set grid\n"
     << "set key top right box opaque\n"
     << "set offsets graph 0.05, graph 0.05, graph 0.05, graph 0.05\n"
     << "set logscale x\n"
     << "set yrange [-2:*]\n"
     << "set xlabel 'bytes per frame on the wire [MB] (fovea chunk codec, 1200-byte datagrams; log scale)'\n"
     << "set ylabel 'input points displaced by more than the MAR at their eccentricity [%]'\n"
     << "set title 'perceptual error against size'\n"
     << "plot ";
  // Lines join the presets of one slope in the left panel (sizes fall from FREF to
  // F1); in the right panel the times do not order them, so points only. ACUITY's
  // many rows (margin x floor) are labelled for the first slope only: repeated for
  // every slope, their labels covered each other and the points.
  auto series = [&](int x_col, int y_col, bool lines) {
    std::ostringstream p;
    for (std::size_t s = 0; s < slopes.size(); ++s) {
      for (int family = 0; family < families; ++family) {
        if (s > 0 || family > 0) p << ", \\\n     ";
        const std::size_t index = static_cast<std::size_t>(families) * s + static_cast<std::size_t>(family);
        p << "'" << data_name << "' index " << index << " using " << x_col << ':' << y_col
          << (lines ? " with linespoints lw 1.5 pt " : " with points pt ") << (5 + 2 * static_cast<int>(s) + family)
          << (family == 1 && lines ? " dt 4" : "") << " ps 1.6 lc " << s + 1 << " title '"
          << (family == 1 ? "ACUITY, " : "") << "m = " << csvNumber(slopes[s]) << "'";
        if (family == 1 && s > 0) continue;
        p << ", \\\n     '' index " << index << " using " << x_col << ':' << y_col
          << ":1 with labels offset char " << (s == 0 ? "1.2,0.8" : s == 1 ? "1.2,-0.8" : "-2.5,0.8") << " tc lt "
          << s + 1 << " notitle";
      }
    }
    return p.str();
  };
  gp << series(3, 6, true);
  for (std::size_t s = 0; s < slopes.size(); ++s) {
    if (slopes[s] == context.reference_slope) continue;  // the same as its solid line
    gp << ", \\\n     '" << data_name << "' index " << static_cast<std::size_t>(families) * s
       << " using 3:8 with linespoints dt 2 lw 1 pt "
       << (4 + 2 * static_cast<int>(s)) << " ps 1.3 lc " << s + 1 << " title 'm = " << csvNumber(slopes[s])
       << ", judged by an m = " << csvNumber(context.reference_slope) << " eye'";
  }
  gp << "\n"
     << "unset logscale x\n"
     << "set key top left box opaque\n"
     << "set xlabel 'CPU time per frame [ms], median: back-projection through sampled output'\n"
     << "set ylabel 'RMS distance from each input point to its representative [mm]'\n"
     << "set title 'geometric error against time'\n"
     << "plot " << series(4, 5, false) << "\n"
     << "unset multiplot\n";
  return writeFile(script_path, gp.str());
}

}  // namespace fovea::tools
