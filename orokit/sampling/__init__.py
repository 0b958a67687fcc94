"""orokit.sampling"""
