// cpm stream as a user meets it (the built program, in its own process):
// the whole file is checked against cpmd's limits before anything is sent.
// The files are generated here from closed forms (a multi-sine and its
// derivative), apart from the checker: the row where the speed first goes
// over the limit is known before cpm reads the file.
#ifdef CPM_EXE
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace cpm {
namespace {

namespace fs = std::filesystem;

struct Result {
  int status = -1;
  std::string out, err;
};

std::string slurp(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

struct Temp {
  fs::path dir = fs::temp_directory_path() / ("cpm-stream-" + std::to_string(getpid()));
  Temp() { fs::create_directories(dir); }
  ~Temp() { fs::remove_all(dir); }
};

Result cpm(const std::string& args, const Temp& t) {
  const std::string cmd = std::string(CPM_EXE) + " " + args + " >" + (t.dir / "out").string() + " 2>" +
                          (t.dir / "err").string();
  const int rc = std::system(cmd.c_str());
  Result r;
  r.status = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  r.out = slurp(t.dir / "out");
  r.err = slurp(t.dir / "err");
  return r;
}

const char* kModel = "config/machine.yaml";
constexpr double kLimit = 0.5;        // m/s, the default limits.velocity
constexpr double kAccelLimit = 5.0;   // m/s^2, the default limits.acceleration
constexpr double kStep = 1e-3;        // s between rows
constexpr int kRows = 30001;          // 30 s

// A multi-sine about the workspace's middle, starting at rest (a raised
// cosine over the first second) and swelling to its largest at 9.8 s (an
// envelope 0.3 + 0.7 sin^2(pi t / 19.6 s)): p = c + k e(t) s(t),
// v = k (e' s + e s'), a = k (e'' s + 2 e' s' + e s'').
struct MultiSine {
  double phase = 0.0, k = 1.0;
  // A common first tone (its speed's largest values recur every half
  // period, so the envelope decides where the record falls) and one of
  // each axis' own.
  static constexpr double w[3][2] = {{2.5, 5.7}, {2.5, 4.3}, {2.5, 6.9}};
  static constexpr double a[3][2] = {{0.030, 0.004}, {0.020, 0.003}, {0.012, 0.002}};
  static void envelope(double t, double& e, double& de, double& dde) {
    const double W = M_PI / 19.6;
    const double g = 0.3 + 0.7 * std::sin(W * t) * std::sin(W * t);
    const double dg = 0.7 * W * std::sin(2 * W * t), ddg = 1.4 * W * W * std::cos(2 * W * t);
    double r = 1, dr = 0, ddr = 0;
    if (t < 1.0) {
      r = 0.5 * (1 - std::cos(M_PI * t));
      dr = 0.5 * M_PI * std::sin(M_PI * t);
      ddr = 0.5 * M_PI * M_PI * std::cos(M_PI * t);
    }
    e = r * g;
    de = dr * g + r * dg;
    dde = ddr * g + 2 * dr * dg + r * ddg;
  }
  void at(double t, double p[3], double v[3], double acc[3]) const {
    double e, de, dde;
    envelope(t, e, de, dde);
    for (int i = 0; i < 3; ++i) {
      double s = 0, ds = 0, dds = 0;
      for (int j = 0; j < 2; ++j) {
        const double q = w[i][j] * t + (j + 1) * phase + i;
        s += a[i][j] * std::sin(q);
        ds += a[i][j] * w[i][j] * std::cos(q);
        dds -= a[i][j] * w[i][j] * w[i][j] * std::sin(q);
      }
      p[i] = (i == 2 ? 0.377 : 0.425) + k * e * s;  // the soft limits' middle
      v[i] = k * (de * s + e * ds);
      acc[i] = k * (dde * s + 2 * de * ds + e * dds);
    }
  }
  [[nodiscard]] double speed(int row) const {
    double p[3], v[3], acc[3];
    at(row * kStep, p, v, acc);
    return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  }
  void write(const fs::path& f, int rows) const {
    std::FILE* o = std::fopen(f.c_str(), "w");
    std::fprintf(o, "t,x,y,z,vx,vy,vz\n");
    for (int r = 0; r < rows; ++r) {
      double p[3], v[3], acc[3];
      at(r * kStep, p, v, acc);
      std::fprintf(o, "%.6f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f\n", r * kStep, p[0], p[1], p[2], v[0], v[1], v[2]);
    }
    std::fclose(o);
  }
};

// The multi-sine whose speed first passes kLimit at data row `row` (1-based):
// a phase where that row's speed is a record by 0.1 %, scaled to pass the
// limit there by 0.05 %.
MultiSine over_at(int row) {
  const int i0 = row - 1;
  for (int n = 0; n < 2000; ++n) {
    MultiSine m;
    m.phase = n * 0.01;
    double before = 0;
    for (int r = 0; r < i0; ++r) before = std::max(before, m.speed(r));
    const double here = m.speed(i0);
    if (here < before * 1.001) continue;
    m.k = kLimit * 1.0005 / here;
    return m;
  }
  ADD_FAILURE() << "no phase puts a speed record at row " << row;
  return {};
}

TEST(CpmStream, AFileOverTheSpeedLimitAtRow9802IsRefusedBeforeAnythingIsSent) {
  Temp t;
  const MultiSine m = over_at(9802);
  // The test's own premises: under the limits up to that row, over it there.
  double amax = 0;
  for (int r = 0; r < 9801; ++r) {
    double p[3], v[3], acc[3];
    m.at(r * kStep, p, v, acc);
    amax = std::max(amax, std::sqrt(acc[0] * acc[0] + acc[1] * acc[1] + acc[2] * acc[2]));
    ASSERT_LE(m.speed(r), kLimit) << r;
  }
  ASSERT_LT(amax, kAccelLimit);
  ASSERT_GT(m.speed(9801), kLimit);
  const fs::path f = t.dir / "multisine.csv";
  m.write(f, kRows);
  // --dry-run, and a real run with the daemon's config (whose limits are the
  // defaults' speed and acceleration): refused before cpmd is even reached
  // (there is none here), naming the row, the figure and the limit.
  for (const std::string mode : {"--dry-run", "--config config/sim.yaml"}) {
    SCOPED_TRACE(mode);
    const Result r = cpm("stream " + f.string() + " --model " + kModel + " " + mode, t);
    EXPECT_EQ(r.status, 1) << r.out << r.err;
    EXPECT_NE(r.err.find("row 9802 (line 9803), the stretch from t = 9.8010 s to 9.8020 s"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("speed 0.50025"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("exceeds the limit 0.5 m/s"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("nothing sent"), std::string::npos) << r.err;
    EXPECT_EQ(r.out.find("setpoints sent"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("approach"), std::string::npos) << r.out;
  }
  // The same file cut before that row passes.
  m.write(f, 9801);
  const Result ok = cpm("stream " + f.string() + " --model " + kModel + " --dry-run", t);
  EXPECT_EQ(ok.status, 0) << ok.err;
}

TEST(CpmStream, AFileEndingAtSpeedGetsAStopAppendedAndChecked) {
  Temp t;
  MultiSine m;
  m.k = 0.5;  // well within the limits
  const fs::path f = t.dir / "at_speed.csv";
  m.write(f, 4001);
  const double v_end = m.speed(4000);
  ASSERT_GT(v_end, 0.02);
  const Result r = cpm("stream " + f.string() + " --model " + kModel + " --dry-run", t);
  ASSERT_EQ(r.status, 0) << r.err;
  char want[64];
  std::snprintf(want, sizeof want, "ends at %.1f mm/s", v_end * 1e3);
  EXPECT_NE(r.out.find(want), std::string::npos) << r.out;
  // Half the acceleration limit from v_end to rest: T = v / 2.5 m/s^2, on the file's step.
  const double T = std::max(2.0, std::ceil(v_end / (0.5 * kAccelLimit) / kStep)) * kStep;
  std::snprintf(want, sizeof want, "a stop of %.3f s", T);
  EXPECT_NE(r.out.find(want), std::string::npos) << r.out;

  // A file that ends at speed toward the soft limit, too close to stop
  // within it: refused, naming the stop.
  std::ofstream(f) << "t,x,y,z,vx,vy,vz\n0,0.57,0.425,0.3,0,0,0\n0.1,0.59,0.425,0.3,0.4,0,0\n";
  const Result near = cpm("stream " + f.string() + " --model " + kModel + " --dry-run", t);
  EXPECT_EQ(near.status, 1) << near.out;
  EXPECT_NE(near.err.find("the stop appended after the last row"), std::string::npos) << near.err;
}

}  // namespace
}  // namespace cpm
#endif
