// Boost.Geometry models of the site's polygons for the checks (site_check*.cpp).
#pragma once

// Boost 1.74's Boost.Geometry includes a deprecated Boost.Math header (a #pragma message).
#ifndef BOOST_ALLOW_DEPRECATED_HEADERS
#define BOOST_ALLOW_DEPRECATED_HEADERS
#endif
// GCC 12 reports -Wmaybe-uninitialized inside Boost.Geometry's relate and envelope code (its
// rescale policy's factor, the envelope's box), false positives at -O1 and above.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include <boost/geometry.hpp>
#include <boost/geometry/geometries/box.hpp>
#include <boost/geometry/geometries/point_xy.hpp>
#include <boost/geometry/geometries/polygon.hpp>
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
#include <string>

#include "agv/site/site.hpp"

namespace agv::site::detail {

namespace bg = boost::geometry;
using BgPoint = bg::model::d2::point_xy<double>;
using BgPolygon = bg::model::polygon<BgPoint, /*clockwise=*/false, /*closed=*/true>;
using BgBox = bg::model::box<BgPoint>;

BgPolygon to_bg(const Polygon& p);

// Drops a repeated closing vertex and consecutive repeats, reorients a clockwise polygon; then
// "" when p is a simple polygon of positive area, else what is wrong with it.
std::string normalise_polygon(Polygon* p);

// Interiors intersect (touching edges or corners do not count).
bool interiors_intersect(const BgPolygon& a, const BgPolygon& b);

// Distance of a point to the polygon's boundary (mm).
double boundary_distance_mm(const BgPolygon& poly, Vec2 p);

}  // namespace agv::site::detail
