"""orokit.tiling"""
