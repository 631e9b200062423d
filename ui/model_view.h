#pragma once
/// A 3D view of meshes (the reference model at its target pose in the room,
/// later the reconstruction). The only VTK code of the GUI lives behind this
/// class, so that no other file includes VTK headers.

#include <QString>
#include <QWidget>
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"

namespace arpos::ui {

class ModelView : public QWidget {
  Q_OBJECT
 public:
  explicit ModelView(QWidget* parent = nullptr);
  ~ModelView() override;

  /// Shows `mesh_in_model` mapped by `room_from_model` in colour (r, g, b in
  /// [0, 1]); replaces any mesh with the same `slot` name.
  void SetMesh(const std::string& slot, const TriangleMesh& mesh_in_model,
               const Rigid3d& room_from_model, double r, double g, double b, double opacity = 1.0);
  /// The same with a colour per vertex (RGB, one per mesh vertex).
  void SetColoredMesh(const std::string& slot, const TriangleMesh& mesh_in_model, const Rigid3d& room_from_model,
                      const std::vector<std::array<std::uint8_t, 3>>& vertex_rgb, double opacity = 1.0);
  /// Small markers (octahedra of `radius_m`) at points in the room, in one slot.
  void SetPoints(const std::string& slot, const std::vector<Eigen::Vector3d>& points_in_room, double r, double g,
                 double b, double radius_m = 0.004);
  /// Removes one slot (no error if it is not shown).
  void RemoveMesh(const std::string& slot);
  void ClearMeshes();
  /// Shows room axes (x red, y green, z blue) of the given length at the origin.
  void ShowRoomAxes(double length_m);
  /// Frames what is shown: the camera looks at the middle of the meshes'
  /// points (0.2 to 99.8 percentile along each of its axes, so that a
  /// few stray landmarks do not shrink the rest to a speck) from as close as
  /// fits them all in the view. With a subject (SetViewSubject) it looks at
  /// the patient from the patient's left and above, anterior up; without
  /// one along its current direction. Until the user turns or zooms the
  /// view, it is framed again whenever the view changes size.
  void ResetCamera();
  /// The patient's pose in the room that ResetCamera views from (reference
  /// model frame: x left, y posterior, z superior); nullopt: none.
  void SetViewSubject(const std::optional<Rigid3d>& room_from_model);
  /// Renders and reads back the current image (for screenshots and tests).
  QImage Grab();

 signals:
  /// Shift + left click on a mesh: its slot, the point in the room and in
  /// the mesh's own frame (room_from_model^-1 of the point).
  void Picked(QString slot, Eigen::Vector3d point_in_room, Eigen::Vector3d point_in_mesh_frame);
  /// Shift + left click that hit no mesh (`slot` empty) or hit `slot`.
  void PickMissed(QString slot);

 protected:
  /// A view framed by ResetCamera is framed again at its new size until the
  /// user turns or zooms it.
  void resizeEvent(QResizeEvent* event) override;

 private:
  void PickAt(int x, int y);
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arpos::ui
