// pcl_reference: run PCL's NormalEstimation, PFHEstimation, FPFHEstimation and
// FPFHEstimationOMP on .xyz clouds and dump the results (and the neighbour table PCL used)
// as raw little-endian binaries, or time the stages.
//
// Usage:
//   pcl_reference (--k K | --radius R) [--viewpoint X Y Z] [--features LIST]
//                 [--threads N] [--out DIR] [--concat] [--time] [--normals-in FILE]
//                 [--unsorted-tree] [--check-table] FILE.xyz [FILE.xyz ...]
//
//   LIST is a comma-separated subset of: normals, normals_omp, pfh, fpfh, fpfh_omp
//   (default: normals,pfh,fpfh). pfh/fpfh/fpfh_omp need normals: they come from
//   NormalEstimation (normals), NormalEstimationOMP (normals_omp) or --normals-in.
//
// Output (--out DIR): one cloud (a single file, or --concat) is written into DIR itself;
// several clouds go to DIR/<file stem>/. Files, all little-endian, C order:
//   points.f32 (n,3)   normals.f32 (n,3)   curvature.f32 (n,)
//   pfh.f32 (n,125)    fpfh.f32 (n,33)     fpfh_omp.f32 (n,33)
//   k-NN:   neighbors.i32 (n,k)   sqdist.f32 (n,k)
//   radius: indptr.i64 (n+1)      indices.i32 (nnz)   sqdist.f32 (nnz)
//   meta.json
// The neighbour table is obtained from the very KdTree object that was handed to every
// estimator with setSearchMethod, queried the way pcl::Feature queries it
// (nearestKSearch(cloud, i, k, ...) / radiusSearch(cloud, i, r, ..., max_nn = 0)).
// --check-table (needs --out) hands the estimators a KdTree subclass that compares every
// query they make with that table and records queries/mismatches in meta.json.
// --unsorted-tree uses KdTree(false), what PCL 1.13 builds when no search method is set.
//
// --time prints one JSON line with wall-clock seconds per stage summed over all clouds (t_*),
// and the process CPU seconds (all threads) of the same stages (cpu_*).

#include <pcl/features/fpfh.h>
#include <pcl/features/fpfh_omp.h>
#include <pcl/features/normal_3d.h>
#include <pcl/features/normal_3d_omp.h>
#include <pcl/features/pfh.h>
#include <pcl/pcl_config.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <limits>
#include <set>
#include <sstream>
#include <string>
#include <sys/stat.h>
#include <time.h>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// CPU seconds of the whole process (all threads): on a loaded machine this, not wall time,
// is what a stage cost.
double cpu_now() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// Wall and CPU time of one stage, added to (wall, cpu) on stop().
struct Stopwatch {
  Clock::time_point w0 = Clock::now();
  double c0 = cpu_now();
  void stop(double &wall, double &cpu) const {
    wall += seconds_since(w0);
    cpu += cpu_now() - c0;
  }
};

[[noreturn]] void die(const std::string &msg) {
  std::cerr << "pcl_reference: " << msg << "\n";
  std::exit(2);
}

struct Options {
  int k = 0;
  double radius = 0.0;
  float vp[3] = {0.f, 0.f, 0.f};
  std::set<std::string> features = {"normals", "pfh", "fpfh"};
  int threads = 1;
  std::string out_dir;
  bool concat = false;
  bool time = false;
  bool sorted_tree = true;
  bool check_table = false;
  std::string normals_in;
  std::vector<std::string> files;
};

void usage() {
  std::cerr
      << "usage: pcl_reference (--k K | --radius R) [--viewpoint X Y Z]\n"
         "         [--features normals,normals_omp,pfh,fpfh,fpfh_omp] [--threads N]\n"
         "         [--out DIR] [--concat] [--time] [--normals-in FILE] [--unsorted-tree]\n"
         "         [--check-table]\n"
         "         FILE.xyz [FILE.xyz ...]\n";
}

Options parse_args(int argc, char **argv) {
  Options o;
  bool have_k = false, have_r = false;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto need = [&](int n) {
      if (i + n >= argc) die("missing value after " + a);
    };
    if (a == "--k") {
      need(1);
      o.k = std::atoi(argv[++i]);
      have_k = true;
    } else if (a == "--radius") {
      need(1);
      o.radius = std::strtod(argv[++i], nullptr);
      have_r = true;
    } else if (a == "--viewpoint") {
      need(3);
      for (int j = 0; j < 3; ++j) o.vp[j] = std::strtof(argv[++i], nullptr);
    } else if (a == "--features") {
      need(1);
      o.features.clear();
      std::stringstream ss(argv[++i]);
      std::string f;
      while (std::getline(ss, f, ','))
        if (!f.empty()) o.features.insert(f);
    } else if (a == "--threads") {
      need(1);
      o.threads = std::atoi(argv[++i]);
    } else if (a == "--out") {
      need(1);
      o.out_dir = argv[++i];
    } else if (a == "--concat") {
      o.concat = true;
    } else if (a == "--time") {
      o.time = true;
    } else if (a == "--check-table") {
      o.check_table = true;
    } else if (a == "--unsorted-tree") {
      o.sorted_tree = false;
    } else if (a == "--normals-in") {
      need(1);
      o.normals_in = argv[++i];
    } else if (a == "-h" || a == "--help") {
      usage();
      std::exit(0);
    } else if (!a.empty() && a[0] == '-' && a.size() > 1) {
      usage();
      die("unknown option " + a);
    } else {
      o.files.push_back(a);
    }
  }
  if (have_k == have_r) {
    usage();
    die("give exactly one of --k and --radius");
  }
  if (have_k && o.k < 1) die("--k must be >= 1");
  if (have_r && !(o.radius > 0)) die("--radius must be > 0");
  if (o.threads < 1) die("--threads must be >= 1");
  if (o.check_table && o.out_dir.empty()) die("--check-table needs --out");
  if (o.files.empty()) {
    usage();
    die("no input files");
  }
  for (const auto &f : o.features)
    if (f != "normals" && f != "normals_omp" && f != "pfh" && f != "fpfh" && f != "fpfh_omp")
      die("unknown feature '" + f + "'");
  if (o.features.count("normals") && o.features.count("normals_omp"))
    die("give only one of normals and normals_omp");
  if (!o.normals_in.empty() && (o.features.count("normals") || o.features.count("normals_omp")))
    die("--normals-in replaces normal estimation: drop normals/normals_omp from --features");
  bool needs_normals = o.features.count("pfh") || o.features.count("fpfh") ||
                       o.features.count("fpfh_omp");
  if (needs_normals && o.normals_in.empty() && !o.features.count("normals") &&
      !o.features.count("normals_omp"))
    o.features.insert("normals");
  if (!o.normals_in.empty() && (o.concat ? false : o.files.size() != 1))
    die("--normals-in needs a single cloud (one file, or --concat)");
  return o;
}

// Whitespace-separated "x y z" per line, parsed with operator>> into float (libstdc++
// uses strtof, so this is the correctly rounded float32 of the decimal text).
void read_xyz(const std::string &path, pcl::PointCloud<pcl::PointXYZ> &cloud) {
  std::ifstream in(path);
  if (!in) die("cannot open " + path);
  std::string line;
  std::size_t lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    std::istringstream ls(line);
    float x, y, z;
    if (!(ls >> x)) continue;  // blank line
    if (!(ls >> y >> z)) die(path + ":" + std::to_string(lineno) + ": expected x y z");
    cloud.push_back(pcl::PointXYZ(x, y, z));
  }
}

// Normals either as raw float32 (n,3) or (n,4) [with curvature] when the name ends in .f32,
// else as text "nx ny nz [curvature]" per line ("nan" accepted).
void read_normals(const std::string &path, std::size_t n, pcl::PointCloud<pcl::Normal> &normals) {
  normals.clear();
  auto ends_with = [](const std::string &s, const std::string &suf) {
    return s.size() >= suf.size() && s.compare(s.size() - suf.size(), suf.size(), suf) == 0;
  };
  if (ends_with(path, ".f32")) {
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    if (!in) die("cannot open " + path);
    std::size_t bytes = static_cast<std::size_t>(in.tellg());
    in.seekg(0);
    std::size_t cols = 0;
    if (bytes == n * 3 * sizeof(float)) cols = 3;
    else if (bytes == n * 4 * sizeof(float)) cols = 4;
    else die(path + ": size does not match n*3 or n*4 float32");
    std::vector<float> buf(n * cols);
    in.read(reinterpret_cast<char *>(buf.data()), bytes);
    for (std::size_t i = 0; i < n; ++i) {
      const float *r = &buf[i * cols];
      normals.push_back(pcl::Normal(r[0], r[1], r[2], cols == 4 ? r[3] : 0.f));
    }
  } else {
    std::ifstream in(path);
    if (!in) die("cannot open " + path);
    std::string line;
    while (std::getline(in, line)) {
      std::istringstream ls(line);
      std::string tok;
      std::vector<float> v;
      while (ls >> tok) v.push_back(std::strtof(tok.c_str(), nullptr));
      if (v.empty()) continue;
      if (v.size() < 3) die(path + ": expected nx ny nz [curvature]");
      normals.push_back(pcl::Normal(v[0], v[1], v[2], v.size() > 3 ? v[3] : 0.f));
    }
    if (normals.size() != n) die(path + ": number of normals does not match number of points");
  }
  normals.width = static_cast<std::uint32_t>(normals.size());
  normals.height = 1;
}

void mkdir_p(const std::string &dir) {
  std::string cur;
  std::stringstream ss(dir);
  std::string part;
  if (!dir.empty() && dir[0] == '/') cur = "/";
  while (std::getline(ss, part, '/')) {
    if (part.empty()) continue;
    cur += part + "/";
    ::mkdir(cur.c_str(), 0777);
  }
  struct stat st;
  if (::stat(dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) die("cannot create " + dir);
}

template <typename T>
void write_raw(const std::string &path, const std::vector<T> &v) {
  std::ofstream out(path, std::ios::binary);
  if (!out) die("cannot write " + path);
  out.write(reinterpret_cast<const char *>(v.data()), static_cast<std::streamsize>(v.size() * sizeof(T)));
  if (!out) die("write failed: " + path);
}

std::string json_escape(const std::string &s) {
  std::string r;
  for (char c : s) {
    if (c == '"' || c == '\\') r += '\\';
    r += c;
  }
  return r;
}

std::string stem_of(const std::string &path) {
  std::string base = path.substr(path.find_last_of('/') == std::string::npos ? 0 : path.find_last_of('/') + 1);
  auto dot = base.find_last_of('.');
  return dot == std::string::npos ? base : base.substr(0, dot);
}

// Neighbour table in search order: k-NN as n rows of k, radius as CSR.
struct Table {
  std::vector<std::int64_t> indptr;  // n+1
  std::vector<std::int32_t> indices;
  std::vector<float> sqdist;
};

// A pcl::search::KdTree that compares every (cloud, index) query an estimator makes against a
// precomputed table, to prove the written table is the one the estimators used. pcl::Feature
// only ever calls these two overloads (feature.hpp: search_method_surface_).
class CheckingKdTree : public pcl::search::KdTree<pcl::PointXYZ> {
 public:
  using Base = pcl::search::KdTree<pcl::PointXYZ>;
  using Base::nearestKSearch;
  using Base::radiusSearch;
  explicit CheckingKdTree(bool sorted) : Base(sorted) {}
  const Table *table = nullptr;
  mutable std::atomic<long> queries{0}, mismatches{0};

  int nearestKSearch(const PointCloud &cloud, pcl::index_t index, int k, pcl::Indices &k_indices,
                     std::vector<float> &k_sqr_distances) const override {
    int r = Base::nearestKSearch(cloud, index, k, k_indices, k_sqr_distances);
    check(index, k_indices, k_sqr_distances);
    return r;
  }
  int radiusSearch(const PointCloud &cloud, pcl::index_t index, double radius, pcl::Indices &k_indices,
                   std::vector<float> &k_sqr_distances, unsigned int max_nn = 0) const override {
    int r = Base::radiusSearch(cloud, index, radius, k_indices, k_sqr_distances, max_nn);
    check(index, k_indices, k_sqr_distances);
    return r;
  }

 private:
  void check(pcl::index_t index, const pcl::Indices &idx, const std::vector<float> &d) const {
    if (!table) return;
    ++queries;
    const std::int64_t b = table->indptr[index], e = table->indptr[index + 1];
    bool ok = static_cast<std::int64_t>(idx.size()) == e - b && d.size() == idx.size();
    for (std::int64_t j = b; ok && j < e; ++j)
      ok = table->indices[j] == idx[j - b] &&
           std::memcmp(&table->sqdist[j], &d[j - b], sizeof(float)) == 0;
    if (!ok) ++mismatches;
  }
};

struct Times {
  double read = 0, kdtree = 0, normals = 0, pfh = 0, fpfh = 0, fpfh_omp = 0;
  double c_kdtree = 0, c_normals = 0, c_pfh = 0, c_fpfh = 0, c_fpfh_omp = 0;
  std::size_t n_points = 0, n_clouds = 0;
};

template <typename Est>
void set_search(Est &est, const Options &o, const pcl::search::KdTree<pcl::PointXYZ>::Ptr &tree) {
  est.setSearchMethod(tree);
  if (o.k > 0) est.setKSearch(o.k);
  else est.setRadiusSearch(o.radius);
}

void process_cloud(const Options &o, const std::vector<std::string> &files, const std::string &out_dir,
                   Times &times) {
  using Cloud = pcl::PointCloud<pcl::PointXYZ>;
  auto t0 = Clock::now();
  Cloud::Ptr cloud(new Cloud);
  for (const auto &f : files) read_xyz(f, *cloud);
  cloud->width = static_cast<std::uint32_t>(cloud->size());
  cloud->height = 1;
  cloud->is_dense = true;
  for (const auto &p : cloud->points)
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) cloud->is_dense = false;
  times.read += seconds_since(t0);
  const std::size_t n = cloud->size();
  if (n == 0) die("empty cloud from " + files.front());
  times.n_points += n;
  times.n_clouds += 1;

  // One tree for every estimator; the features' initCompute sees that its input cloud is
  // already the surface and does not rebuild it.
  std::shared_ptr<CheckingKdTree> checker;
  pcl::search::KdTree<pcl::PointXYZ>::Ptr tree;
  if (o.check_table) {
    checker = std::make_shared<CheckingKdTree>(o.sorted_tree);
    tree = checker;
  } else {
    tree.reset(new pcl::search::KdTree<pcl::PointXYZ>(o.sorted_tree));
  }
  {
    Stopwatch sw;
    tree->setInputCloud(cloud);
    sw.stop(times.kdtree, times.c_kdtree);
  }

  // The neighbour table (untimed), from the same tree object, queried exactly as pcl::Feature
  // does (feature.hpp: tree_->nearestKSearch / radiusSearch(cloud, index, ..., max_nn = 0)).
  // The qualified calls bypass CheckingKdTree's overrides.
  Table table;
  std::size_t min_nn = SIZE_MAX, max_nn = 0;
  if (!out_dir.empty()) {
    using Search = pcl::search::Search<pcl::PointXYZ>;
    pcl::Indices idx;
    std::vector<float> dist;
    table.indptr.assign(n + 1, 0);
    for (std::size_t i = 0; i < n; ++i) {
      if (o.k > 0) {
        tree->Search::nearestKSearch(*cloud, static_cast<pcl::index_t>(i), o.k, idx, dist);
        if (static_cast<int>(idx.size()) != o.k)
          die("k-NN search returned fewer than k neighbours (cloud smaller than k?)");
      } else {
        tree->Search::radiusSearch(*cloud, static_cast<pcl::index_t>(i), o.radius, idx, dist, 0);
      }
      for (std::size_t j = 0; j < idx.size(); ++j) {
        table.indices.push_back(static_cast<std::int32_t>(idx[j]));
        table.sqdist.push_back(dist[j]);
      }
      table.indptr[i + 1] = static_cast<std::int64_t>(table.indices.size());
      min_nn = std::min(min_nn, idx.size());
      max_nn = std::max(max_nn, idx.size());
    }
    if (checker) checker->table = &table;
  }

  pcl::PointCloud<pcl::Normal>::Ptr normals(new pcl::PointCloud<pcl::Normal>);
  if (!o.normals_in.empty()) {
    read_normals(o.normals_in, n, *normals);
  } else if (o.features.count("normals_omp")) {
    pcl::NormalEstimationOMP<pcl::PointXYZ, pcl::Normal> ne(static_cast<unsigned>(o.threads));
    ne.setInputCloud(cloud);
    set_search(ne, o, tree);
    ne.setViewPoint(o.vp[0], o.vp[1], o.vp[2]);
    Stopwatch sw;
    ne.compute(*normals);
    sw.stop(times.normals, times.c_normals);
  } else if (o.features.count("normals")) {
    pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
    ne.setInputCloud(cloud);
    set_search(ne, o, tree);
    ne.setViewPoint(o.vp[0], o.vp[1], o.vp[2]);
    Stopwatch sw;
    ne.compute(*normals);
    sw.stop(times.normals, times.c_normals);
  }
  if (!normals->empty() && normals->size() != n) die("normal estimation returned a wrong size");

  pcl::PointCloud<pcl::PFHSignature125> pfh;
  if (o.features.count("pfh")) {
    pcl::PFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::PFHSignature125> est;
    est.setInputCloud(cloud);
    est.setInputNormals(normals);
    set_search(est, o, tree);
    Stopwatch sw;
    est.compute(pfh);
    sw.stop(times.pfh, times.c_pfh);
  }
  pcl::PointCloud<pcl::FPFHSignature33> fpfh, fpfh_omp;
  if (o.features.count("fpfh")) {
    pcl::FPFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::FPFHSignature33> est;
    est.setInputCloud(cloud);
    est.setInputNormals(normals);
    set_search(est, o, tree);
    Stopwatch sw;
    est.compute(fpfh);
    sw.stop(times.fpfh, times.c_fpfh);
  }
  if (o.features.count("fpfh_omp")) {
    pcl::FPFHEstimationOMP<pcl::PointXYZ, pcl::Normal, pcl::FPFHSignature33> est(static_cast<unsigned>(o.threads));
    est.setInputCloud(cloud);
    est.setInputNormals(normals);
    set_search(est, o, tree);
    Stopwatch sw;
    est.compute(fpfh_omp);
    sw.stop(times.fpfh_omp, times.c_fpfh_omp);
  }

  if (out_dir.empty()) return;
  mkdir_p(out_dir);
  const std::string d = out_dir + "/";
  {
    std::vector<float> v(n * 3);
    for (std::size_t i = 0; i < n; ++i) {
      v[3 * i] = (*cloud)[i].x;
      v[3 * i + 1] = (*cloud)[i].y;
      v[3 * i + 2] = (*cloud)[i].z;
    }
    write_raw(d + "points.f32", v);
  }
  if (!normals->empty()) {
    std::vector<float> v(n * 3), c(n);
    for (std::size_t i = 0; i < n; ++i) {
      v[3 * i] = (*normals)[i].normal_x;
      v[3 * i + 1] = (*normals)[i].normal_y;
      v[3 * i + 2] = (*normals)[i].normal_z;
      c[i] = (*normals)[i].curvature;
    }
    write_raw(d + "normals.f32", v);
    write_raw(d + "curvature.f32", c);
  }
  if (!pfh.empty()) {
    std::vector<float> v(n * 125);
    for (std::size_t i = 0; i < n; ++i) std::memcpy(&v[125 * i], pfh[i].histogram, 125 * sizeof(float));
    write_raw(d + "pfh.f32", v);
  }
  auto dump33 = [&](const pcl::PointCloud<pcl::FPFHSignature33> &h, const std::string &name) {
    if (h.empty()) return;
    std::vector<float> v(n * 33);
    for (std::size_t i = 0; i < n; ++i) std::memcpy(&v[33 * i], h[i].histogram, 33 * sizeof(float));
    write_raw(d + name, v);
  };
  dump33(fpfh, "fpfh.f32");
  dump33(fpfh_omp, "fpfh_omp.f32");

  const std::size_t nnz = table.indices.size();
  if (o.k > 0) {
    write_raw(d + "neighbors.i32", table.indices);  // (n, k)
  } else {
    write_raw(d + "indptr.i64", table.indptr);
    write_raw(d + "indices.i32", table.indices);
  }
  write_raw(d + "sqdist.f32", table.sqdist);

  std::size_t nan_normals = 0;
  for (const auto &nm : normals->points)
    if (!std::isfinite(nm.normal_x) || !std::isfinite(nm.normal_y) || !std::isfinite(nm.normal_z)) ++nan_normals;

  std::ofstream m(d + "meta.json");
  char buf[64];
  m << "{\n  \"n\": " << n << ",\n";
  if (o.k > 0) m << "  \"search\": \"knn\",\n  \"k\": " << o.k << ",\n";
  else {
    std::snprintf(buf, sizeof buf, "%.17g", o.radius);
    m << "  \"search\": \"radius\",\n  \"radius\": " << buf << ",\n";
  }
  m << "  \"viewpoint\": [";
  for (int j = 0; j < 3; ++j) {
    std::snprintf(buf, sizeof buf, "%.9g", o.vp[j]);
    m << buf << (j < 2 ? ", " : "");
  }
  m << "],\n  \"tree\": \"pcl::search::KdTree(sorted=" << (o.sorted_tree ? "true" : "false") << ")\",\n";
  m << "  \"normals_source\": \""
    << (o.normals_in.empty() ? (o.features.count("normals_omp") ? "NormalEstimationOMP" : "NormalEstimation")
                             : "file:" + json_escape(o.normals_in))
    << "\",\n";
  m << "  \"nan_normals\": " << nan_normals << ",\n";
  m << "  \"neighbors_total\": " << nnz << ",\n  \"neighbors_min\": " << min_nn
    << ",\n  \"neighbors_max\": " << max_nn << ",\n";
  if (checker)
    m << "  \"table_check\": {\"queries\": " << checker->queries.load() << ", \"mismatches\": "
      << checker->mismatches.load() << "},\n";
  m << "  \"features\": [";
  bool first = true;
  for (const auto &f : o.features) {
    m << (first ? "" : ", ") << "\"" << f << "\"";
    first = false;
  }
  m << "],\n  \"threads\": " << o.threads << ",\n";
  m << "  \"files\": [";
  for (std::size_t j = 0; j < files.size(); ++j) m << (j ? ", " : "") << "\"" << json_escape(files[j]) << "\"";
  m << "],\n  \"pcl_version\": \"" << PCL_VERSION_PRETTY << "\"\n}\n";
}

}  // namespace

int main(int argc, char **argv) {
  Options o = parse_args(argc, argv);
  Times times;
  if (o.concat || o.files.size() == 1) {
    process_cloud(o, o.files, o.out_dir, times);
  } else {
    for (const auto &f : o.files)
      process_cloud(o, {f}, o.out_dir.empty() ? "" : o.out_dir + "/" + stem_of(f), times);
  }
  if (o.time) {
    std::printf(
        "{\"mode\": \"%s\", \"clouds\": %zu, \"n_points\": %zu, \"%s\": %.9g, \"threads\": %d, "
        "\"t_read\": %.6f, \"t_kdtree\": %.6f, \"t_normals\": %.6f, \"t_kdtree_normals\": %.6f, "
        "\"t_pfh\": %.6f, \"t_fpfh\": %.6f, \"t_fpfh_omp\": %.6f, "
        "\"cpu_kdtree_normals\": %.6f, \"cpu_pfh\": %.6f, \"cpu_fpfh\": %.6f, \"cpu_fpfh_omp\": %.6f, "
        "\"pcl_version\": \"%s\"}\n",
        o.concat ? "concat" : (o.files.size() == 1 ? "single" : "per-file"), times.n_clouds, times.n_points,
        o.k > 0 ? "k" : "radius", o.k > 0 ? static_cast<double>(o.k) : o.radius, o.threads, times.read,
        times.kdtree, times.normals, times.kdtree + times.normals, times.pfh, times.fpfh, times.fpfh_omp,
        times.c_kdtree + times.c_normals, times.c_pfh, times.c_fpfh, times.c_fpfh_omp, PCL_VERSION_PRETTY);
  }
  return 0;
}
