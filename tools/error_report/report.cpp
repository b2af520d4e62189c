#include "tools/error_report/report.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <utility>

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

bool isAcuity(const ConfigSummary& c) { return c.preset.rfind("ACUITY", 0) == 0; }

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
         "ratio_p95_true_surface,source,share_above_mar_surface,share_above_reference_mar_surface,rms_mm_surface,"
         "fuse_ms_median,map_frame_points,map_surfels\n";
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
          << (all && c.have_truth ? csvNumber(c.truth.ratio_p95) : "") << ',' << c.source << ','
          << (all && c.have_surface ? csvNumber(c.surface_share_above_mar) : "") << ','
          << (all && c.have_surface ? csvNumber(c.surface_share_above_reference_mar) : "") << ','
          << (all && c.have_surface ? csvNumber(c.surface_rms_mm) : "") << ','
          << (all && c.isMap() ? csvNumber(c.fuse_ms_median) : "") << ','
          << (all && c.isMap() ? csvNumber(c.map_frame_points) : "") << ','
          << (all && c.isMap() ? csvNumber(c.map_surfels) : "") << '\n';
    };
    for (const RegionSummary& r : c.regions) row(r);
    row(c.all);
  }
  return writeFile(path, out.str());
}

Result<std::vector<ConfigSummary>> readCsvSummaries(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Result<std::vector<ConfigSummary>>(ErrorCode::kIoError, path + ": cannot open");
  const auto split = [](const std::string& line) {
    std::vector<std::string> fields;
    std::size_t start = 0;
    for (std::size_t comma; (comma = line.find(',', start)) != std::string::npos; start = comma + 1) {
      fields.push_back(line.substr(start, comma - start));
    }
    fields.push_back(line.substr(start));
    return fields;
  };
  std::string line;
  std::getline(in, line);
  const std::vector<std::string> header = split(line);
  std::map<std::string, std::size_t> column;
  for (std::size_t i = 0; i < header.size(); ++i) column[header[i]] = i;
  for (const char* name : {"preset", "m", "region", "frames", "points_out", "bytes_per_frame", "time_ms_median", "rms_mm",
                           "share_above_mar", "share_above_reference_mar"}) {
    if (!column.count(name)) return Result<std::vector<ConfigSummary>>(ErrorCode::kParseError, path + ": no column " + name);
  }
  std::vector<ConfigSummary> configs;
  for (int number = 2; std::getline(in, line); ++number) {
    const std::vector<std::string> f = split(line);
    const std::string where = path + ":" + std::to_string(number) + ": ";
    if (f.size() != header.size()) {
      return Result<std::vector<ConfigSummary>>(ErrorCode::kParseError, where + "not " + std::to_string(header.size()) + " fields");
    }
    if (f[column["region"]] != "all") continue;
    bool ok = true;
    const auto number_at = [&](const char* name) {
      const std::string& text = f[column[name]];
      char* end = nullptr;
      const double v = std::strtod(text.c_str(), &end);
      if (text.empty() || end != text.c_str() + text.size()) ok = false;
      return v;
    };
    ConfigSummary c;
    c.preset = f[column["preset"]];
    if (column.count("source")) c.source = f[column["source"]];  // (older reports: the frame only)
    c.slope = number_at("m");
    c.frames = static_cast<int>(number_at("frames"));
    c.time_ms_median = number_at("time_ms_median");
    c.all.name = "all";
    c.all.points_out = number_at("points_out");
    c.all.wire_bytes = number_at("bytes_per_frame");
    c.all.rms_mm = number_at("rms_mm");
    c.all.share_above_mar = number_at("share_above_mar");
    c.all.share_above_reference_mar = number_at("share_above_reference_mar");
    if (!ok) return Result<std::vector<ConfigSummary>>(ErrorCode::kParseError, where + "a plotted field is not a number");
    configs.push_back(std::move(c));
  }
  return configs;
}

Result<std::string> readMarkdownCamera(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Result<std::string>(ErrorCode::kIoError, path + ": cannot open");
  constexpr std::string_view kStart = "- camera: ", kEnd = "; gaze: ";
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(kStart, 0) != 0) continue;
    const std::size_t end = line.find(kEnd);
    if (end != std::string::npos) return line.substr(kStart.size(), end - kStart.size());
  }
  return Result<std::string>(ErrorCode::kParseError, path + ": no '- camera: ...; gaze: ' line");
}

namespace {

// The sources side by side (--sources with map): every row, each judged against
// the true surface by the nearest sent point.
std::string sourcesMarkdown(const ReportContext& context, const std::vector<ConfigSummary>& configs) {
  std::ostringstream md;
  md << "\n## Frame against map\n\n"
     << "The same measured frames foveated from the frame's own cloud (*frame*) and from the fused surfel map "
        "(*map*, foveation.source = map: the frame fused into the map, then the map's stable surfels the eye sees "
        "and the frame's points the map does not explain, foveated together; docs/map.md), the map warmed up over "
     << context.map_warmup_frames << " frames of the same camera before the first measured frame. "
     << "*above MAR, true surface (nearest)*: the share of the true surface's points (the noiseless twin's frame, "
        "every pixel in range) whose nearest sent point, seen from the eye, is displaced by more than MAR(ecc) "
        "(docs/report/README.md): holes and displaced points both count, for both sources the same way. "
        "*RMS to nearest*: the distance from each true point to its nearest sent point. *time*: thread CPU time per "
        "frame, median: the frame source's back-projection and foveation (scalar reference kernels); the map "
        "source's fusion (scalar reference, one thread) + the eye's view of the map + foveation; *of which fusion* "
        "is the fusion's median alone. The map's other columns in report.csv (rms_mm, share_above_mar) measure "
        "its output against its own input (the surfels and unexplained points), not against the frame.\n\n"
     << "| source | preset | m | points out | bytes / frame | above MAR, true surface (nearest) | above MAR of the m = "
     << fixed(context.reference_slope, 3) << " eye (nearest) | RMS to nearest [mm] | CPU time / frame [ms] | of which "
        "fusion [ms] | map surfels sent | frame points unexplained |\n"
     << "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const ConfigSummary& c : configs) {
    md << "| " << c.source << " | " << c.preset << " | " << fixed(c.slope, 3) << " | " << fixed(c.all.points_out, 0)
       << " | " << fixed(c.bytesPerFrame() / 1e6, 3) << " MB | "
       << (c.have_surface ? percent(c.surface_share_above_mar) : std::string("-")) << " | "
       << (c.have_surface ? percent(c.surface_share_above_reference_mar) : std::string("-")) << " | "
       << (c.have_surface ? fixed(c.surface_rms_mm, 1) : std::string("-")) << " | " << fixed(c.time_ms_median, 2)
       << " | " << (c.isMap() ? fixed(c.fuse_ms_median, 2) : std::string("-")) << " | "
       << (c.isMap() ? fixed(c.map_surfels, 0) : std::string("-")) << " | "
       << (c.isMap() ? fixed(c.map_frame_points, 0) : std::string("-")) << " |\n";
  }
  return md.str();
}

// The page's title, the run's command and camera, and what each column measures.
void writeIntro(std::ostream& md, const ReportContext& context) {
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
}

// The plots, or how to draw them when gnuplot did not.
void writePlotsParagraph(std::ostream& md, const std::vector<ConfigSummary>& configs, bool have_plot) {
  const bool any_acuity = std::any_of(configs.begin(), configs.end(), isAcuity);
  if (have_plot) {
    md << "![bytes and time against error](" << kMainPlot.png << ")\n\n";
    if (any_acuity) {
      md << "The plot names at most " << kMainPlotAcuitySettings << " ACUITY settings; every one is in the tables "
         << "below and here:\n\n![every ACUITY setting](" << kAcuityPlot.png << ")\n\n";
    }
  } else {
    md << "(No plot: gnuplot was not found. `cd` here and run `gnuplot " << kMainPlot.script << "`"
       << (any_acuity ? std::string(" and `gnuplot ") + kAcuityPlot.script + "`" : std::string()) << ".)\n\n";
  }
}

// A row per configuration, all regions pooled (and against the true surface when measured).
void writeConfigTable(std::ostream& md, const ReportContext& context, const std::vector<ConfigSummary>& configs) {
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
}

// A row per region of each configuration.
void writeRegionTable(std::ostream& md, const ReportContext& context, const std::vector<ConfigSummary>& configs) {
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
}

// The step in alpha/MAR at each region border.
void writeBorderSteps(std::ostream& md, const std::vector<ConfigSummary>& configs) {
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
}

// Observations that follow from the numbers alone; the interpretation is in README.md.
void writeRegionVerdicts(std::ostream& md, const std::vector<ConfigSummary>& configs) {
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
}

}  // namespace

Status writeMarkdown(const std::string& path, const ReportContext& context, const std::vector<ConfigSummary>& every_config,
                     bool have_plot) {
  // The tables below are the frame source's (their error is against each input
  // point); the map's rows are compared with them in their own section.
  std::vector<ConfigSummary> configs;
  std::copy_if(every_config.begin(), every_config.end(), std::back_inserter(configs),
               [](const ConfigSummary& c) { return !c.isMap(); });
  const bool any_map = configs.size() != every_config.size();
  std::ostringstream md;
  writeIntro(md, context);
  writePlotsParagraph(md, configs, have_plot);
  writeConfigTable(md, context, configs);
  writeRegionTable(md, context, configs);
  writeBorderSteps(md, configs);
  writeRegionVerdicts(md, configs);
  if (any_map) md << sourcesMarkdown(context, every_config);
  md << context.extra_markdown;
  if (!context.date_utc.empty()) md << "\n";
  return writeFile(path, md.str());
}

namespace {

// The slopes of the run, in its order.
std::vector<double> slopesOf(const std::vector<ConfigSummary>& configs) {
  std::vector<double> slopes;
  for (const ConfigSummary& c : configs) {
    if (std::find(slopes.begin(), slopes.end(), c.slope) == slopes.end()) slopes.push_back(c.slope);
  }
  return slopes;
}

// configName puts ACUITY's margin right after the preset: "ACUITY k=0.50 floor ...".
constexpr std::string_view kMarginTag = " k=";

// The name without its margin: the rows one line of report_acuity.png joins, which
// differ only in k ("ACUITY floor 1mm*r^2").
std::string withoutMargin(const std::string& name) {
  const std::size_t tag = name.find(kMarginTag);
  if (tag == std::string::npos) return name;
  const std::size_t end = name.find(' ', tag + 1);
  return name.substr(0, tag) + (end == std::string::npos ? "" : name.substr(end));
}

// A gnuplot index block of the plot data: a comment and one line per configuration.
struct PlotBlock {
  std::string comment;
  std::vector<const ConfigSummary*> rows;
};

// The blocks as gnuplot's data file: the columns' header, then each block, two
// blank lines between blocks. `slopes` numbers each row's slope (1, 2, ...: the
// colour of that slope on report.png).
std::string plotData(const std::vector<PlotBlock>& blocks, const std::vector<double>& slopes) {
  std::ostringstream data;
  data << "# label m bytes_per_frame_MB cpu_time_ms_median rms_mm share_above_mar_percent points_out "
          "share_above_reference_mar_percent slope_number\n";
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    if (b > 0) data << "\n\n";
    data << "# " << blocks[b].comment << "\n";
    for (const ConfigSummary* c : blocks[b].rows) {
      const std::string label = isAcuity(*c) ? c->preset.substr(std::string("ACUITY ").size()) : c->preset;
      const auto slope = std::find(slopes.begin(), slopes.end(), c->slope);
      data << '"' << label << "\" " << csvNumber(c->slope) << ' ' << csvNumber(c->bytesPerFrame() / 1e6) << ' '
           << csvNumber(c->time_ms_median) << ' ' << csvNumber(c->all.rms_mm) << ' '
           << csvNumber(100.0 * c->all.share_above_mar) << ' ' << csvNumber(c->all.points_out) << ' '
           << csvNumber(100.0 * c->all.share_above_reference_mar) << ' ' << (slope - slopes.begin()) + 1 << "\n";
    }
  }
  return data.str();
}

// The bytes axis: logarithmic when the bytes span a decade or more (FREF against
// F1), with ticks at 1, 2 and 5 of each decade; linear when they span less, where
// gnuplot's logarithmic axis draws no tick at all.
std::string bytesAxis(const std::vector<const ConfigSummary*>& rows) {
  double lo = 0.0, hi = 0.0;
  for (const ConfigSummary* c : rows) {
    if (c->bytesPerFrame() <= 0.0) continue;
    lo = lo > 0.0 ? std::min(lo, c->bytesPerFrame()) : c->bytesPerFrame();
    hi = std::max(hi, c->bytesPerFrame());
  }
  const bool log = lo > 0.0 && hi >= 10.0 * lo;
  return std::string(log ? "set logscale x\nset xtics add (0.02, 0.05, 0.2, 0.5, 2, 5)\n" : "unset logscale x\n") +
         "set xlabel 'bytes per frame on the wire [MB] (fovea chunk codec, 1200-byte datagrams" + (log ? "; log scale" : "") +
         ")'\nset ylabel 'input points displaced by more than the MAR at their eccentricity [%]'\n";
}
const char* const kTimeAxis = "unset logscale x\nset xtics autofreq\n"
                              "set xlabel 'CPU time per frame [ms], median: back-projection through sampled output'\n"
                              "set ylabel 'RMS distance from each input point to its representative [mm]'\n";

std::string scriptHeader(const PlotFiles& files, const std::string& what, int rows, int width, int height,
                         const ReportContext& context) {
  std::ostringstream gp;
  gp << "# Draws " << files.png << " from " << files.data << "; written by fovea-error-report. Run: gnuplot "
     << files.script << "\n"
     << "set terminal pngcairo size " << width << ',' << height << " font 'sans,11'\n"
     << "set output '" << files.png << "'\n"
     << "set multiplot layout " << rows << ",2 title \"fovea: " << what << ", " << context.camera << ", "
     << context.frames << " frames (scalar reference)\"\n"
     << "set grid\n"
     // The data's own x range, not the next decade; room on the right for FREF's label.
     << "set autoscale xfix\n"
     << "set offsets graph 0.05, graph 0.1, graph 0.05, graph 0.05\n";
  return gp.str();
}

// One plot command's clauses, joined as gnuplot continues a line.
std::string joinClauses(const std::vector<std::string>& clauses) {
  std::string joined;
  for (std::size_t i = 0; i < clauses.size(); ++i) joined += (i > 0 ? ", \\\n     " : "") + clauses[i];
  return joined;
}

// The labels of a block of the paper's presets in a bytes panel: F1 and F3 above
// right of their point, F2 and FREF below right, so that two presets at the same
// point (F2 and F3 on TUM, where nothing lies beyond 30 degrees) stay apart.
void presetLabels(std::vector<std::string>& clauses, std::size_t index, const PlotBlock& block, const std::string& colour) {
  const std::string source = "'' index " + std::to_string(index);
  clauses.push_back(source + " every 2 using 3:6:1 with labels left offset char 1,0.7 tc " + colour + " notitle");
  if (block.rows.size() > 1) {
    clauses.push_back(source + " every 2::1 using 3:6:1 with labels left offset char 1,-0.7 tc " + colour + " notitle");
  }
}

// "F1, F2, F3, FREF": the presets of a block.
std::string presetNames(const PlotBlock& block) {
  std::string names;
  for (const ConfigSummary* c : block.rows) names += (names.empty() ? "" : ", ") + c->preset;
  return names;
}

// report.png: per slope, the paper's presets joined by a line (a colour per slope,
// labelled at the first slope only: the other slopes' lines have the same order
// and their labels covered the first's); the chosen ACUITY settings as points, a
// hollow shape per setting, coloured by slope and named once in the legend; no
// ACUITY labels.
std::pair<std::string, std::string> mainPlot(const ReportContext& context, const std::vector<ConfigSummary>& configs) {
  const std::vector<double> slopes = slopesOf(configs);
  std::vector<PlotBlock> blocks;
  std::vector<std::size_t> preset_block(slopes.size(), SIZE_MAX);
  for (std::size_t s = 0; s < slopes.size(); ++s) {
    PlotBlock block{"m " + csvNumber(slopes[s]) + ", the paper's presets", {}};
    for (const ConfigSummary& c : configs) {
      if (c.slope == slopes[s] && !isAcuity(c)) block.rows.push_back(&c);
    }
    if (block.rows.empty()) continue;
    preset_block[s] = blocks.size();
    blocks.push_back(std::move(block));
  }
  const std::vector<std::string> acuity = mainPlotAcuitySettings(configs);
  std::vector<const ConfigSummary*> plotted;
  for (const std::string& name : acuity) {
    PlotBlock block{name + ", a row per slope", {}};
    for (const ConfigSummary& c : configs) {
      if (c.preset == name) block.rows.push_back(&c);
    }
    blocks.push_back(std::move(block));
  }
  for (const PlotBlock& block : blocks) plotted.insert(plotted.end(), block.rows.begin(), block.rows.end());
  const std::size_t first_acuity_block = blocks.size() - acuity.size();
  // Hollow shapes no preset line uses (those are 4 + 2s hollow and 5 + 2s filled).
  constexpr int kAcuityPointTypes[kMainPlotAcuitySettings] = {12, 10, 14};

  const std::string data = kMainPlot.data;
  const auto clauses = [&](int x_col, int y_col, bool bytes) {
    const std::string columns = " using " + std::to_string(x_col) + ':' + std::to_string(y_col);
    std::vector<std::string> out;
    for (std::size_t s = 0; s < slopes.size(); ++s) {
      if (preset_block[s] == SIZE_MAX) continue;
      const PlotBlock& block = blocks[preset_block[s]];
      const std::string style = " pt " + std::to_string(5 + 2 * static_cast<int>(s)) + " ps 1.6 lc " + std::to_string(s + 1);
      out.push_back("'" + data + "' index " + std::to_string(preset_block[s]) + columns +
                    (bytes ? " with linespoints lw 1.5" : " with points") + style + " title '" +
                    (s == 0 ? presetNames(block) + ", " : "") + "m = " + csvNumber(slopes[s]) + "'");
      if (s > 0) continue;
      if (bytes) {
        presetLabels(out, preset_block[s], block, "lt 1");
      } else {
        out.push_back("'' index " + std::to_string(preset_block[s]) + columns +
                      ":1 with labels offset char 1.5,0.9 tc lt 1 notitle");
      }
    }
    if (bytes) {
      for (std::size_t s = 0; s < slopes.size(); ++s) {
        if (preset_block[s] == SIZE_MAX || slopes[s] == context.reference_slope) continue;  // the same as its solid line
        out.push_back("'" + data + "' index " + std::to_string(preset_block[s]) +
                      " using 3:8 with linespoints dt 2 lw 1 pt " + std::to_string(4 + 2 * static_cast<int>(s)) +
                      " ps 1.3 lc " + std::to_string(s + 1) + " title 'm = " + csvNumber(slopes[s]) +
                      ", judged by an m = " + csvNumber(context.reference_slope) + " eye'");
      }
    }
    for (std::size_t a = 0; a < acuity.size(); ++a) {
      const std::string pt = std::to_string(kAcuityPointTypes[a]);
      out.push_back("'" + data + "' index " + std::to_string(first_acuity_block + a) + columns +
                    ":9 with points pt " + pt + " ps 1.8 lw 1.5 lc variable notitle");
      if (bytes) out.push_back("keyentry with points pt " + pt + " ps 1.8 lw 1.5 lc 'black' title '" + acuity[a] + "'");
    }
    return joinClauses(out);
  };

  std::ostringstream gp;
  gp << scriptHeader(kMainPlot, "bytes and time against error", 1, 1500, 620, context)
     << "set key top right box opaque\n"
     << "set yrange [-2:*]\n"
     << bytesAxis(plotted) << "set title 'perceptual error against size (a colour per slope m)'\n"
     << "plot " << clauses(3, 6, true) << "\n"
     << "unset key\n"
     << kTimeAxis << "set title 'geometric error against time (symbols as on the left)'\n"
     << "plot " << clauses(4, 5, false) << "\n"
     << "unset multiplot\n";
  return {plotData(blocks, slopes), gp.str()};
}

// report_acuity.png: a row of panels per slope; the paper's presets in black, and
// a line per ACUITY setting but its margin (withoutMargin) in a colour and a
// hollow shape of its own. Only the first line with several margins has its
// points labelled (k=...), below left: it is the lowest and rightmost, the
// others share its order, and their labels covered it. The legend stands right
// of the time panel, outside the data (hence the wider picture).
std::pair<std::string, std::string> acuityPlot(const ReportContext& context, const std::vector<ConfigSummary>& configs) {
  std::vector<std::string> lines;  // withoutMargin of each ACUITY row, in the order of the run
  for (const ConfigSummary& c : configs) {
    if (isAcuity(c) && std::find(lines.begin(), lines.end(), withoutMargin(c.preset)) == lines.end()) {
      lines.push_back(withoutMargin(c.preset));
    }
  }
  constexpr int kPointTypes[] = {6, 8, 4, 10, 12, 14, 1, 2, 3};
  std::vector<double> slopes;
  for (double m : slopesOf(configs)) {
    if (std::any_of(configs.begin(), configs.end(), [&](const ConfigSummary& c) { return isAcuity(c) && c.slope == m; })) {
      slopes.push_back(m);
    }
  }
  std::vector<PlotBlock> blocks;
  std::ostringstream panels;
  for (double m : slopes) {
    std::vector<std::string> bytes_clauses, time_clauses;
    std::vector<const ConfigSummary*> plotted;
    // A block as a line in the bytes panel and as points, named, in the time panel.
    const auto add = [&](PlotBlock block, const std::string& style, const std::string& title) {
      const std::string index = "'" + std::string(kAcuityPlot.data) + "' index " + std::to_string(blocks.size());
      bytes_clauses.push_back(index + " using 3:6 with linespoints " + style + " notitle");
      time_clauses.push_back(index + " using 4:5 with points " + style + " title '" + title + "'");
      plotted.insert(plotted.end(), block.rows.begin(), block.rows.end());
      blocks.push_back(std::move(block));
      return blocks.size() - 1;
    };
    PlotBlock presets{"m " + csvNumber(m) + ", the paper's presets", {}};
    for (const ConfigSummary& c : configs) {
      if (c.slope == m && !isAcuity(c)) presets.rows.push_back(&c);
    }
    if (!presets.rows.empty()) {
      const std::string names = presetNames(presets);
      const std::size_t index = add(std::move(presets), "lw 1.5 pt 5 ps 1.4 lc 'black'", names);
      presetLabels(bytes_clauses, index, blocks[index], "'black'");
      time_clauses.push_back("'' index " + std::to_string(index) +
                             " using 4:5:1 with labels right offset char -0.8,0.9 tc 'black' notitle");
    }
    bool labelled = false;
    for (std::size_t l = 0; l < lines.size(); ++l) {
      PlotBlock block{"m " + csvNumber(m) + ", " + lines[l], {}};
      for (const ConfigSummary& c : configs) {
        if (c.slope == m && isAcuity(c) && withoutMargin(c.preset) == lines[l]) block.rows.push_back(&c);
      }
      if (block.rows.empty()) continue;
      const bool label = block.rows.size() > 1 && !labelled;
      const std::string title = block.rows.size() > 1 ? lines[l] : block.rows.front()->preset;
      const std::string colour = std::to_string(l + 1);
      const std::size_t index = add(std::move(block),
                                    "lw 1.5 pt " + std::to_string(kPointTypes[l % std::size(kPointTypes)]) + " ps 1.6 lc " + colour,
                                    title);
      if (label) {
        bytes_clauses.push_back("'' index " + std::to_string(index) +
                                " using 3:6:1 with labels right offset char -0.6,-0.9 tc lt " + colour + " notitle");
        labelled = true;
      }
    }
    const std::string slope = "m = " + csvNumber(m);
    panels << "unset key\n"
           << "set yrange [-2:*]\n"
           << bytesAxis(plotted) << "set title '" << slope
           << ": perceptual error against size (a line per setting through its margins k)'\n"
           << "plot " << joinClauses(bytes_clauses) << "\n"
           << "set key outside right top vertical box\n"
           << "set autoscale y\n"
           << kTimeAxis << "set title '" << slope << ": geometric error against time'\n"
           << "plot " << joinClauses(time_clauses) << "\n";
  }
  const int rows = static_cast<int>(slopes.size());
  std::ostringstream gp;
  gp << scriptHeader(kAcuityPlot, "every ACUITY setting, bytes and time against error", rows,
                     1800, 60 + 640 * rows, context)
     << panels.str() << "unset multiplot\n";
  return {plotData(blocks, slopesOf(configs)), gp.str()};
}

}  // namespace

std::vector<std::string> mainPlotAcuitySettings(const std::vector<ConfigSummary>& configs) {
  pipeline::AcuityConfig standard;
  standard.preset = pipeline::Preset::kAcuity;
  pipeline::AcuityConfig floored = standard;
  floored.floor_per_m2 = 0.001;
  pipeline::AcuityConfig refined = standard;
  refined.level_margin = 0.3;
  refined.refine_passes = 1;
  std::vector<std::string> run;  // the run's ACUITY settings, in its order
  for (const ConfigSummary& c : configs) {
    if (isAcuity(c) && std::find(run.begin(), run.end(), c.preset) == run.end()) run.push_back(c.preset);
  }
  std::vector<std::string> chosen;
  for (const pipeline::AcuityConfig& quoted : {standard, floored, refined}) {
    const std::string name = configName(quoted);
    if (std::find(run.begin(), run.end(), name) != run.end()) chosen.push_back(name);
  }
  for (const std::string& name : run) {
    if (chosen.size() == kMainPlotAcuitySettings) break;
    if (std::find(chosen.begin(), chosen.end(), name) == chosen.end()) chosen.push_back(name);
  }
  return chosen;
}

Result<std::vector<PlotFiles>> writePlotFiles(const std::string& dir, const ReportContext& context,
                                              const std::vector<ConfigSummary>& configs) {
  std::vector<PlotFiles> written;
  const auto write = [&](const PlotFiles& files, const std::pair<std::string, std::string>& data_and_script) {
    if (Status s = writeFile(dir + "/" + files.data, data_and_script.first); !s) return s;
    if (Status s = writeFile(dir + "/" + files.script, data_and_script.second); !s) return s;
    written.push_back(files);
    return Status::ok();
  };
  if (Status s = write(kMainPlot, mainPlot(context, configs)); !s) return s;
  if (std::any_of(configs.begin(), configs.end(), isAcuity)) {
    if (Status s = write(kAcuityPlot, acuityPlot(context, configs)); !s) return s;
  }
  return written;
}

}  // namespace fovea::tools
