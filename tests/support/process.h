// Running programs under test as separate processes, and scratch folders.
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <random>
#include <regex>
#include <string>

#include "tests/support/test_time.h"

namespace fovea::test {

struct ProcessResult {
  int exit_code = -1;  // -1: did not start or did not exit normally
  std::string output;  // stdout and stderr
};

// Runs `command` through /bin/sh and collects its output.
inline ProcessResult runCommand(const std::string& command) {
  ProcessResult r;
  std::FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  char buffer[4096];
  std::size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) r.output.append(buffer, n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// A program running beside the test (a service), its stdout and stderr
// collected through a pipe. The destructor kills it if it is still running.
class BackgroundProcess {
 public:
  explicit BackgroundProcess(const std::string& command) {
    int fds[2];
    if (pipe(fds) != 0) return;
    pid_ = fork();
    if (pid_ == 0) {
      dup2(fds[1], 1);
      dup2(fds[1], 2);
      close(fds[0]);
      close(fds[1]);
      execl("/bin/sh", "sh", "-c", ("exec " + command).c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
    close(fds[1]);
    fd_ = fds[0];
  }
  ~BackgroundProcess() {
    if (pid_ > 0 && !exited_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    if (fd_ >= 0) close(fd_);
  }
  BackgroundProcess(const BackgroundProcess&) = delete;
  BackgroundProcess& operator=(const BackgroundProcess&) = delete;

  bool started() const { return pid_ > 0 && fd_ >= 0; }
  const std::string& output() const { return output_; }

  // Reads output until it contains `text` (true) or the program closes its
  // output (false), giving up after waitLimitSeconds(expected_s): the time the
  // text takes natively, scaled for this build and a loaded machine (test_time.h).
  bool waitFor(const std::string& text, double expected_s) {
    return waitUntil([&] { return output_.find(text) != std::string::npos; }, expected_s);
  }
  // The same for a pattern (a count in a status line that must leave zero).
  bool waitForMatch(const std::regex& pattern, double expected_s) {
    return waitUntil([&] { return std::regex_search(output_, pattern); }, expected_s);
  }

  // Sends a signal without waiting (SIGHUP to a service).
  bool signal(int signal_number) { return pid_ > 0 && !exited_ && kill(pid_, signal_number) == 0; }

  // Sends `signal`, waits for the exit (expected_s natively, scaled as waitFor),
  // collects the rest of the output. Returns the exit code (-1: killed by a
  // signal or did not exit in time).
  int stop(int signal_number, double expected_s) {
    if (pid_ <= 0) return -1;
    kill(pid_, signal_number);
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(waitLimitSeconds(expected_s));
    int status = 0;
    while (waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > end) return -1;
      readSome(20);
    }
    exited_ = true;
    while (readSome(100)) {
    }
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }

 private:
  template <class Seen>
  bool waitUntil(Seen seen, double expected_s) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(waitLimitSeconds(expected_s));
    while (!seen()) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now());
      if (left.count() <= 0 || !readSome(static_cast<int>(left.count()))) return false;
    }
    return true;
  }
  // Waits up to timeout_ms for output and appends it; false at end of output or timeout.
  bool readSome(int timeout_ms) {
    if (fd_ < 0) return false;
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, timeout_ms) <= 0) return false;
    char buffer[4096];
    const ssize_t n = read(fd_, buffer, sizeof buffer);
    if (n <= 0) return false;
    output_.append(buffer, static_cast<std::size_t>(n));
    return true;
  }

  pid_t pid_ = -1;
  int fd_ = -1;
  bool exited_ = false;
  std::string output_;
};

// A fresh folder under the system's temporary directory, removed with its contents.
class TempDir {
 public:
  TempDir() {
    path_ = std::filesystem::temp_directory_path() /
            ("fovea-test-" + std::to_string(::getpid()) + "-" + std::to_string(std::random_device{}()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string path() const { return path_.string(); }
  std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

}  // namespace fovea::test
