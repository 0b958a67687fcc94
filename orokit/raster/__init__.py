"""orokit.raster"""
