// SerialQueue: tasks run in order and never overlap; RunAndWait runs after everything posted
// before it, on the calling thread when the queue is idle; RunHereOrPost runs on the calling
// thread only when the queue is idle, and otherwise queues without waiting.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>
#include <vector>

#include "engine/runtime/serial_queue.h"

namespace weft {
namespace {

TEST(SerialQueueTest, RunAndWaitOnIdleQueueRunsOnCallingThread) {
  SerialQueue q;
  q.WaitIdle();
  std::thread::id ran_on;
  q.RunAndWait([&] { ran_on = std::this_thread::get_id(); });
  EXPECT_EQ(ran_on, std::this_thread::get_id());
  EXPECT_EQ(q.pending(), 0u);
}

TEST(SerialQueueTest, RunAndWaitRunsAfterPostedTasksInOrder) {
  SerialQueue q;
  std::vector<int> order;   // touched only by queue tasks, which never overlap
  q.Post([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
    order.push_back(1);
  });
  q.Post([&] { order.push_back(2); });
  q.RunAndWait([&] { order.push_back(3); });
  ASSERT_EQ(order, (std::vector<int>{1, 2, 3}));
}

TEST(SerialQueueTest, TasksPostedDuringAnInlineRunWaitForIt) {
  SerialQueue q;
  std::atomic<int> running{0};
  std::atomic<int> max_running{0};
  std::vector<int> order;
  auto enter = [&] {
    int now = ++running;
    int seen = max_running.load();
    while (now > seen && !max_running.compare_exchange_weak(seen, now)) {}
  };
  std::atomic<bool> inline_started{false};
  std::thread poster([&] {
    while (!inline_started) std::this_thread::yield();
    for (int i = 0; i < 3; ++i) q.Post([&, i] {
      enter();
      order.push_back(10 + i);
      --running;
    });
  });
  q.RunAndWait([&] {
    enter();
    inline_started = true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    order.push_back(0);
    --running;
  });
  poster.join();
  q.WaitIdle();
  EXPECT_EQ(max_running.load(), 1);
  EXPECT_EQ(order, (std::vector<int>{0, 10, 11, 12}));
}

TEST(SerialQueueTest, RunHereOrPostRunsHereOnlyWhenIdle) {
  SerialQueue q;
  std::thread::id ran_on;
  EXPECT_TRUE(q.RunHereOrPost([&] { ran_on = std::this_thread::get_id(); }));
  EXPECT_EQ(ran_on, std::this_thread::get_id());

  std::vector<int> order;   // touched only by queue tasks, which never overlap
  std::atomic<bool> release{false};
  q.Post([&] {
    while (!release) std::this_thread::yield();
    order.push_back(1);
  });
  std::thread::id second_on;
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_FALSE(q.RunHereOrPost([&] {   // the queue is busy: queued behind, not waited for
    second_on = std::this_thread::get_id();
    order.push_back(2);
  }));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
  release = true;
  q.WaitIdle();
  EXPECT_EQ(order, (std::vector<int>{1, 2}));
  EXPECT_NE(second_on, std::this_thread::get_id());
  // Idle again: the next one runs here, after the others.
  EXPECT_TRUE(q.RunHereOrPost([&] { order.push_back(3); }));
  EXPECT_EQ(order, (std::vector<int>{1, 2, 3}));
}

TEST(SerialQueueTest, TasksPostedDuringARunHereWaitForIt) {
  SerialQueue q;
  std::vector<int> order;
  std::atomic<bool> started{false};
  std::thread poster([&] {
    while (!started) std::this_thread::yield();
    q.Post([&] { order.push_back(2); });
  });
  EXPECT_TRUE(q.RunHereOrPost([&] {
    started = true;
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
    order.push_back(1);
  }));
  poster.join();
  q.WaitIdle();
  EXPECT_EQ(order, (std::vector<int>{1, 2}));
}

}  // namespace
}  // namespace weft
