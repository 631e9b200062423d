#include "ui/worker.h"

#include <memory>

namespace arpos::ui {

Worker::Worker(QObject* parent) : QObject(parent) {}

Worker::~Worker() {
  cancel_ = true;
  if (thread_) {
    thread_->wait();
    delete thread_;
  }
}

bool Worker::Start(Job job) {
  if (busy_) return false;
  if (thread_) {
    thread_->wait();
    delete thread_;
  }
  busy_ = true;
  cancel_ = false;
  thread_ = QThread::create([this, job = std::move(job)] {
    ControllerCallbacks callbacks;
    callbacks.progress = [this](const std::string& step, double fraction) {
      emit Progress(QString::fromStdString(step), fraction);
    };
    callbacks.cancel_requested = [this] { return cancel_.load(); };
    bool ok = true;
    QString message;
    try {
      message = QString::fromStdString(job(callbacks));
    } catch (const std::exception& e) {
      ok = false;
      message = QString::fromStdString(e.what());
    }
    busy_ = false;
    emit Finished(ok, message);
  });
  thread_->start();
  return true;
}

bool Worker::Start(Job job, QObject* receiver, std::function<void(bool ok, QString message)> done) {
  if (busy_) return false;
  auto connection = std::make_shared<QMetaObject::Connection>();
  *connection = connect(this, &Worker::Finished, receiver, [connection, done = std::move(done)](bool ok, QString message) {
    QObject::disconnect(*connection);
    done(ok, message);
  });
  if (Start(std::move(job))) return true;
  QObject::disconnect(*connection);
  return false;
}

}  // namespace arpos::ui
