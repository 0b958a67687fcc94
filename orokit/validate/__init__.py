"""orokit.validate"""
